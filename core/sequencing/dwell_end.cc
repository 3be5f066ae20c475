// The end of a dwell (Sequencer::Complete): too many bad or lost samples, a creep between its
// halves beyond the white noise and the sensor's own wander, a mean that does not fit the
// current calibration -- each rejects the pose (announced) or skips the segment (schedule) with
// its reason; otherwise the pose record is made and announced. The rest of the sequencer is in
// sequencer.cc.
#include <fmt/format.h>

#include <cmath>
#include <limits>
#include <string>

#include "core/sequencing/sequencer.h"

namespace turncal {
namespace {

std::string PoseText(const TablePose& p) {
  return fmt::format("phi {:.3f} gamma {:.3f} psi {:.3f} deg", p.phi_rad * 180 / M_PI,
                     p.gamma_rad * 180 / M_PI, p.psi_rad * 180 / M_PI);
}

}  // namespace

void Sequencer::Complete(double t_s) {
  const bool too_bad = counts_.bad_fraction() > options_.max_bad_fraction;
  if (too_bad || counts_.lost_fraction() > options_.max_lost_fraction) {
    const std::string why =
        too_bad ? fmt::format(
                      "too many bad samples: {} flagged, {} outliers of {} ({:.1f}% > {:.1f}%); "
                      "{} lost",
                      counts_.flagged, counts_.outliers, counts_.used + counts_.bad(),
                      100 * counts_.bad_fraction(), 100 * options_.max_bad_fraction, counts_.lost)
                : fmt::format(
                      "too many lost samples: {} lost of {} ({:.1f}% > {:.1f}%; a bad cable, "
                      "line noise or an overrun?)",
                      counts_.lost, counts_.used + counts_.bad(), 100 * counts_.lost_fraction(),
                      100 * options_.max_lost_fraction);
    if (scheduled()) {
      SkipSegment(t_s, why);
    } else {
      Reject(t_s, why);
    }
    return;
  }
  // The dwell's two halves must agree: a table creeping too slowly for one window to see
  // (0.1 deg/s moves gravity's projection by 2e-3 m/s^2 per second) shows between them, beyond
  // what the white noise and the sensor's own bias wander (options' stillness.bias_drift, at the
  // scale the station identified) explain.
  // (A rate segment's steadiness was checked window by window, with the table's ripple allowed:
  // core/sequencing/rate_steady.h.)
  for (int t = 0; t < 3 && !rate_mode_; ++t) {
    const NoiseProfile& prof = detector_->profile();
    if (!prof.sigma[t] || acc_[t].count() < 4 || first_half_[t].count() < 2) continue;
    const auto n = static_cast<double>(acc_[t].count());
    const auto n1 = static_cast<double>(first_half_[t].count());
    const Eigen::Vector3d m1 = first_half_[t].mean();
    const Eigen::Vector3d m2 = (acc_[t].mean() * n - m1 * n1) / (n - n1);
    // A magnetometer slower than the stream holds each value over several samples.
    const double samples_per_value = n / static_cast<double>(acc_[t].independent());
    for (int a = 0; a < 3; ++a) {
      const double limit = detector_->HalvesDriftLimit(t, a, n1, n - n1, samples_per_value);
      const double drift = std::abs(m2[a] - m1[a]);
      if (!(drift <= limit)) {
        const std::string why = fmt::format(
            "the {} {} mean drifted {:.3g} {} between the halves of the dwell (still limit "
            "{:.3g}): the table crept",
            TriadName(t), "xyz"[a], drift, TriadUnit(t), limit);
        if (scheduled()) {
          SkipSegment(t_s, why);
        } else {
          Reject(t_s, why);
        }
        return;
      }
    }
  }
  PoseRecord record;
  record.pose = pose_;
  if (acc_[kTriadAcc].count() > 0) record.acc = acc_[kTriadAcc].Stats();
  if (acc_[kTriadGyr].count() > 0) record.gyr = acc_[kTriadGyr].Stats();
  if (acc_[kTriadMag].count() > 0) record.mag = acc_[kTriadMag].Stats();
  record.t_start_s = static_cast<double>(t_first_ns_) * 1e-9;
  // The window covers `used` sample periods.
  record.t_end_s = static_cast<double>(t_last_ns_) * 1e-9 + 1.0 / detector_->profile().rate_hz;
  if (std::isfinite(t_first_sensor_s_) && std::isfinite(t_last_sensor_s_) &&
      t_last_sensor_s_ >= t_first_sensor_s_) {
    const auto& prof = detector_->profile();
    record.sensor_t_start_s = t_first_sensor_s_;
    record.sensor_t_end_s =
        t_last_sensor_s_ + (prof.device_period_s ? *prof.device_period_s : 1.0 / prof.rate_hz);
  }
  if (temp_n_ > 0) {
    const double n = static_cast<double>(temp_n_);
    const double mean = temp_sum_ / n;
    record.temp_c = temp_ref_ + mean;
    const double var = temp_n_ > 1 ? std::max(0.0, (temp_sum2_ - n * mean * mean) / (n - 1)) : 0.0;
    record.temp_spread = TemperatureSpread{std::sqrt(var), temp_min_, temp_max_};
  }
  if (!rate_mode_) record.move_in = moves_.TakeEnded();

  if (predictor_) {
    for (int t : {kTriadAcc, kTriadMag}) {
      const auto& stats = t == kTriadAcc ? record.acc : record.mag;
      if (!stats) continue;
      const auto prediction = predictor_(pose_, t);
      if (!prediction) continue;
      const PoseFit fit = CheckPoseMean(*stats, *prediction, options_.pose_check_false_alarm,
                                        t == kTriadAcc ? "accelerometer" : "magnetometer");
      if (fit.fits) continue;
      if (!scheduled()) {
        Reject(t_s, fit.reason);
        return;
      }
      // Does it fit a later scheduled pose? Then the schedule's order is wrong.
      std::string later;
      for (std::size_t j = next_scheduled_ + 1; j < schedule_.size() && later.empty(); ++j) {
        const auto pj = predictor_(schedule_[j], t);
        if (pj && CheckPoseMean(*stats, *pj, options_.pose_check_false_alarm, "").fits) {
          later = fmt::format("; it fits scheduled pose {} ({}): is the schedule's order wrong?",
                              j + 1, PoseText(schedule_[j]));
        }
      }
      SkipSegment(t_s, fit.reason + later);
      return;
    }
  }
  ++captured_;
  // A static pose's gyro mean is the bias now (the Earth's rate, < 7.3e-5 rad/s, is well inside
  // the rate test's limit): the next poses' rate test follows the bias through temperature.
  if (!rate_mode_ && record.gyr && record.gyr->count > 0) {
    detector_->TrackGyroBias(record.gyr->mean,
                             record.temp_c.value_or(std::numeric_limits<double>::quiet_NaN()));
  }
  Emit(SequencerEventKind::kCaptured, t_s,
       fmt::format("{} samples over {:.2f} s{}", counts_.used, record.duration_s(),
                   record.move_in
                       ? fmt::format("; the move here over {:.2f} s", record.move_in->duration_s())
                       : std::string()),
       &record);
  // The next move starts at this dwell's last sample (a rate segment's end attitude is unknown).
  if (rate_mode_) {
    moves_.Abort("a rate segment came between");
  } else {
    moves_.Start(pose_, last_committed_);
  }
  if (scheduled()) {
    ++next_scheduled_;
    NextScheduled(t_s);
    if (state_ == State::kWaiting) state_ = State::kSegmentDone;
  } else {
    state_ = State::kIdle;
  }
}

void Sequencer::Reject(double t_s, std::string reason) {
  ++rejected_;
  moves_.Abort("the pose it led to was rejected");
  Emit(SequencerEventKind::kRejected, t_s, std::move(reason));
  state_ = State::kIdle;
  needed_ = 0;
}

void Sequencer::SkipSegment(double t_s, std::string reason) {
  ++skipped_segments_;
  // Free mode: the skipped segment's samples belong to the move to the next interval.
  if (free_) {
    moves_.Resume();
  } else {
    moves_.Abort("the still segment it led to was skipped");
  }
  Emit(SequencerEventKind::kSegmentSkipped, t_s, std::move(reason));
  counts_ = SampleCounts{};
  needed_ = 0;
  // Wait for the segment to end before looking for the next.
  state_ = detector_ && detector_->still_run() > 0 ? State::kSegmentDone : State::kWaiting;
}

}  // namespace turncal
