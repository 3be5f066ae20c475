#include "core/sequencing/sequencer.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <limits>

namespace turncal {
namespace {

// The moves' time step (core/estimation/move_integrator.h): the device's nominal period, its
// measured rate rounded to whole hertz when within 0.1 % of one (a device clock 20 ppm fast
// measures 499.99 Hz for 500), otherwise the measured period.
double NominalPeriod(const NoiseProfile& profile) {
  const double rate = profile.device_period_s ? 1.0 / *profile.device_period_s : profile.rate_hz;
  const double whole = std::round(rate);
  if (whole >= 1 && std::abs(rate - whole) <= 1e-3 * whole) return 1.0 / whole;
  return 1.0 / rate;
}

// Beyond a window, how long a tick lets a stream be silent before it has stopped (CheckTimeout).
constexpr double kReadStallAllowanceS = 2.0;

}  // namespace

bool SequencerOptions::IsValid(std::string* error) const {
  auto fail = [&](const std::string& m) {
    if (error) *error = m;
    return false;
  };
  if (!(free_max_dwell_s > 0 && free_max_dwell_s <= 3600)) {
    return fail("the free mode's longest interval must be in (0, 3600] s");
  }
  if (!(dwell_s > 0 && dwell_s <= 3600) || !(settle_guard_s >= 0 && settle_guard_s <= 60) ||
      !(still_timeout_s > 0 && still_timeout_s <= 86400)) {
    return fail(
        "dwell must be in (0, 3600] s, settle guard in [0, 60] s, still timeout in (0, "
        "86400] s");
  }
  if (!(max_bad_fraction >= 0 && max_bad_fraction < 1)) {
    return fail("the bad-sample fraction must be in [0, 1)");
  }
  if (!(max_lost_fraction >= 0 && max_lost_fraction < 1)) {
    return fail("the lost-sample fraction must be in [0, 1)");
  }
  if (!(pose_check_false_alarm > 0 && pose_check_false_alarm < 1)) {
    return fail("the pose-check false alarm must be in (0, 1)");
  }
  if (!(progress_step > 0 && progress_step <= 1)) return fail("progress step must be in (0, 1]");
  if (!stillness.IsValid(error) || !noise_meter.IsValid(error) || !rate_steady.IsValid(error) ||
      !moves.IsValid(error)) {
    return false;
  }
  if (noise && !noise->IsValid(error)) return false;
  return true;
}

const char* ToString(SequencerEventKind kind) {
  switch (kind) {
    case SequencerEventKind::kNoiseMeasured:
      return "NOISE_MEASURED";
    case SequencerEventKind::kNoiseRetry:
      return "NOISE_RETRY";
    case SequencerEventKind::kPoseStarted:
      return "POSE_STARTED";
    case SequencerEventKind::kCollecting:
      return "POSE_COLLECTING";
    case SequencerEventKind::kProgress:
      return "POSE_PROGRESS";
    case SequencerEventKind::kCaptured:
      return "POSE_CAPTURED";
    case SequencerEventKind::kRejected:
      return "POSE_REJECTED";
    case SequencerEventKind::kSoakWaiting:
      return "POSE_WAITING";
    case SequencerEventKind::kSegmentSkipped:
      return "SEGMENT_SKIPPED";
    case SequencerEventKind::kScheduleEnd:
      return "SCHEDULE_END";
  }
  return "?";
}

Sequencer::Sequencer(const SequencerOptions& options, Sink sink)
    : options_(options),
      sink_(std::move(sink)),
      meter_(options.noise_meter),
      moves_(options.moves) {}

void Sequencer::Emit(SequencerEventKind kind, double t_s, std::string reason,
                     const PoseRecord* record) {
  if (!sink_) return;
  SequencerEvent e;
  e.kind = kind;
  e.t_s = t_s;
  e.index = index_;
  e.pose = pose_;
  e.collected = counts_.used;
  e.needed = needed_;
  e.counts = counts_;
  e.reason = std::move(reason);
  if (record) e.record = *record;
  sink_(e);
}

void Sequencer::SetDriftScale(int triad, double scale) {
  if (triad < 0 || triad > 2) return;
  drift_scale_[static_cast<std::size_t>(triad)] = std::isfinite(scale) && scale > 0 ? scale : 1.0;
  if (detector_) detector_->SetDriftScale(triad, scale);
}

void Sequencer::SetIdentifiedDrift(int triad, const IdentifiedDrift& identified) {
  if (triad < 0 || triad > 2) return;
  identified_[static_cast<std::size_t>(triad)] = identified;
  drift_scale_[static_cast<std::size_t>(triad)] = identified.scale;
  if (detector_) detector_->SetIdentifiedDrift(triad, identified);
}

void Sequencer::StartDetector(const NoiseProfile& profile, double t_s) {
  detector_ = std::make_unique<StillnessDetector>(profile, options_.stillness);
  for (int t = 0; t < 3; ++t) {
    const auto k = static_cast<std::size_t>(t);
    if (identified_[k]) {
      detector_->SetIdentifiedDrift(t, *identified_[k]);
    } else if (drift_scale_[k] != 1.0) {
      detector_->SetDriftScale(t, drift_scale_[k]);
    }
  }
  moves_.SetPeriod(NominalPeriod(profile));
  if (options_.moves.enabled) {
    // The detector's delay is its window of fed samples; the accepted ones it spans include the
    // outliers dropped meanwhile (9 of 258 in a mip move at 500 Hz).
    move_ring_.assign(2 * static_cast<std::size_t>(detector_->window()) + 16, StillSample{});
    move_head_ = move_size_ = 0;
  }
  required_run_ = detector_->window() +
                  static_cast<std::int64_t>(std::ceil(options_.settle_guard_s * profile.rate_hz));
  if (!options_.noise) {
    const int keep = index_;
    index_ = -1;
    Emit(SequencerEventKind::kNoiseMeasured, t_s,
         profile.Describe() + "; " + detector_->DescribeLimits());
    index_ = keep;
  }
}

bool Sequencer::Announce(const Announcement& a, std::string* error) {
  if (free_) {
    if (error) {
      *error =
          "free mode: the station finds the static intervals itself and takes no poses (hold "
          "the device still in each orientation; next_pose says which to add)";
    }
    return false;
  }
  if (scheduled()) {
    if (error) *error = "the sequencer follows a schedule; announcements are not taken";
    return false;
  }
  soak_why_.clear();
  soak_event_t_s_ = -1e9;
  const double dwell = a.dwell_s.value_or(options_.dwell_s);
  if (!(dwell > 0) || dwell > 3600) {
    if (error) *error = fmt::format("dwell {} s out of range (0, 3600]", dwell);
    return false;
  }
  if (!std::isfinite(a.pose.phi_rad) || !std::isfinite(a.pose.gamma_rad) ||
      !std::isfinite(a.pose.psi_rad)) {
    if (error) *error = "pose angles must be finite";
    return false;
  }
  if (a.pose.is_rate() && !(std::abs(a.pose.rate_radps) >= 0.1 * M_PI / 180 &&
                            std::abs(a.pose.rate_radps) <= 2000 * M_PI / 180)) {
    if (error) *error = "a rate segment's rate must be 0.1 to 2000 deg/s in magnitude";
    return false;
  }
  const double t_s = static_cast<double>(a.t_host_ns) * 1e-9;
  CheckTimeout(a.t_host_ns);
  if (busy()) {
    std::string why =
        fmt::format("superseded: pose {} was announced before this one completed", a.index);
    if (rate_mode_ && rate_ && !rate_->finding().empty()) {
      why += "; the rate was not steady: " + rate_->finding();
    }
    Reject(t_s, why);
  }
  if (a.pose.is_rate()) moves_.Abort("a rate segment came between");
  index_ = a.index;
  pose_ = a.pose;
  has_pose_ = true;
  t_announce_ns_ = a.t_host_ns;
  announced_ = true;
  dwell_s_ = dwell;
  counts_ = SampleCounts{};
  needed_ = 0;
  state_ = State::kWaiting;
  rate_mode_ = a.pose.is_rate();
  rate_.reset();
  if (rate_mode_) {
    const double turn_s = 2 * M_PI / std::abs(a.pose.rate_radps);
    Emit(SequencerEventKind::kPoseStarted, t_s,
         fmt::format("rate {:.3f} deg/s about the {} axis; {:.0f} revolutions of {:.2f} s",
                     a.pose.rate_radps * 180 / M_PI, ToString(a.pose.rate_axis),
                     std::max(1.0, std::ceil(dwell_s_ / turn_s - 1e-9)), turn_s));
    return true;
  }
  Emit(SequencerEventKind::kPoseStarted, t_s, fmt::format("dwell {:.2f} s", dwell_s_));
  return true;
}

bool Sequencer::SetSchedule(std::vector<TablePose> poses, std::string* error) {
  if (poses.empty() || state_ != State::kIdle || scheduled()) {
    if (error) *error = "a schedule needs poses and an idle sequencer without one";
    return false;
  }
  for (const auto& p : poses) {
    if (p.is_rate()) {
      if (error) *error = "a schedule holds static poses only; rate segments are announced";
      return false;
    }
  }
  schedule_ = std::move(poses);
  next_scheduled_ = 0;
  NextScheduled(0.0);
  return true;
}

bool Sequencer::SetFree(std::string* error) {
  if (state_ != State::kIdle || scheduled()) {
    if (error) *error = "free mode needs an idle sequencer without a schedule";
    return false;
  }
  free_ = true;
  moves_.SetResumable(true);
  if (!SetSchedule({TablePose{}}, error)) return false;
  return true;
}

void Sequencer::NextScheduled(double t_s) {
  counts_ = SampleCounts{};
  needed_ = 0;
  if (free_) {
    WaitForPose(TablePose{});
    Emit(SequencerEventKind::kPoseStarted, t_s,
         fmt::format("free: interval {}, at least {:.2f} s still", index_ + 1, dwell_s_));
    return;
  }
  if (next_scheduled_ >= schedule_.size()) {
    state_ = State::kScheduleDone;
    return;
  }
  WaitForPose(schedule_[next_scheduled_]);
  Emit(SequencerEventKind::kPoseStarted, t_s,
       fmt::format("scheduled {} of {}, dwell {:.2f} s", index_ + 1, schedule_.size(), dwell_s_));
}

void Sequencer::WaitForPose(const TablePose& pose) {
  index_ = static_cast<int>(next_scheduled_);
  pose_ = pose;
  has_pose_ = true;
  t_announce_ns_ = std::numeric_limits<std::int64_t>::min();
  announced_ = false;
  dwell_s_ = options_.dwell_s;
  state_ = State::kWaiting;
}

void Sequencer::Interrupt(double t_s, const std::string& why) {
  detector_->Clear();
  held_.reset();
  moves_.Abort("the stream was interrupted");
  move_head_ = move_size_ = 0;
  move_lost_ = move_flagged_ = 0;
  pending_lost_ = pending_flagged_ = pending_outliers_ = 0;
  if (state_ == State::kCollecting) {
    if (scheduled()) {
      SkipSegment(t_s, why);
      // The segment may go on after the gap: only real motion ends it, so the rest of this
      // segment is never taken for the next pose.
      state_ = State::kSegmentDone;
    } else {
      Reject(t_s, why);
    }
  }
  last_motion_ = StillFinding{};
  last_motion_.kind = StillFinding::kFilling;
  last_motion_t_s_ = t_s;
}

void Sequencer::Feed(const StillSample& in) {
  StillSample s = in;
  s.lost_before = in.lost_before + pending_lost_;
  s.flagged_before = pending_flagged_;
  s.outliers_before = pending_outliers_;
  pending_lost_ = pending_flagged_ = pending_outliers_ = 0;
  StillSample evicted;
  bool has_evicted = false;
  const bool still = detector_->Push(s, &evicted, &has_evicted);
  const double t_s = s.t_s();
  if (std::isfinite(s.temp_c)) {
    soak_tracker_.Add(t_s, s.temp_c, soak_ ? soak_->window_s : SoakOptions{}.window_s);
  }
  if (!still && detector_->finding().kind != StillFinding::kFilling) {
    last_motion_ = detector_->finding();
    last_motion_t_s_ = t_s;
  }
  const bool moving = !still && detector_->finding().kind != StillFinding::kFilling;
  if (soak_ && soak_->check_bias && !bias_settled_) {
    if (moving) {
      bias_settle_.Clear();
    } else if (still) {
      bias_settle_.Add(s, soak_->window_s);
    }
  }
  if (has_evicted) {
    while (move_size_ > 0 && move_ring_[move_head_].seq <= evicted.seq) {
      moves_.Add(move_ring_[move_head_]);
      move_head_ = (move_head_ + 1) % move_ring_.size();
      --move_size_;
    }
  }
  if (rate_mode_ && (state_ == State::kWaiting || state_ == State::kCollecting)) {
    FeedRate(s);
    return;
  }
  switch (state_) {
    case State::kIdle:
      break;
    case State::kScheduleDone:
      // A further still segment long enough for a pose, after the last pose's segment ended.
      if (moving) seen_motion_after_schedule_ = true;
      if (seen_motion_after_schedule_ && still &&
          detector_->still_run() ==
              required_run_ + static_cast<std::int64_t>(
                                  std::ceil(options_.dwell_s * detector_->profile().rate_hz))) {
        ++extra_segments_;
      }
      break;
    case State::kWaiting:
      if (still && has_evicted && detector_->still_run() >= required_run_ &&
          evicted.t_host_ns > t_announce_ns_ && SoakSettled(t_s)) {
        StartCollecting(evicted);
      }
      break;
    case State::kCollecting:
      if (!still) {
        const std::string why = fmt::format(
            "motion during the dwell after {:.2f} of {:.2f} s: {}",
            static_cast<double>(counts_.used + counts_.bad()) / detector_->profile().rate_hz,
            dwell_s_, detector_->finding().Describe());
        if (free_ && counts_.used + counts_.bad() >= needed_) {
          Complete(t_s);  // the segment ended after at least the dwell: all of it is the record
        } else if (scheduled()) {
          SkipSegment(t_s, "still segment shorter than the dwell; " + why);
        } else {
          Reject(t_s, why);
        }
      } else if (has_evicted) {
        Commit(evicted);
        if (counts_.used + counts_.bad() >= (free_ ? free_max_needed_ : needed_)) Complete(t_s);
      }
      break;
    case State::kSegmentDone:
      if (moving) state_ = State::kWaiting;
      break;
  }
}

bool Sequencer::SoakSettled(double t_s) {
  if (!soak_ || !announced_) return true;
  if (soak_tracker_.Settled(*soak_, &soak_why_)) {
    if (!soak_->check_bias || bias_settled_) {
      soak_why_.clear();
      return true;
    }
    const HalvesLimit limit = [this](int triad, int axis, double n1, double n2) {
      return detector_->HalvesDriftLimit(triad, axis, n1, n2, detector_->samples_per_value(triad));
    };
    std::string why;
    if (bias_settle_.Settled(soak_->window_s, limit, &why)) {
      bias_settled_ = true;
      soak_why_.clear();
      return true;
    }
    soak_why_ = fmt::format(
        "waiting for the soak at {:.1f} degC: the temperature has settled ({}), "
        "{}",
        soak_->setpoint_c,
        soak_tracker_.latest_c() ? fmt::format("{:.2f} degC", *soak_tracker_.latest_c()) : "", why);
  }
  // Said again every 10 s while the pose waits.
  if (t_s - soak_event_t_s_ >= 10.0) {
    soak_event_t_s_ = t_s;
    Emit(SequencerEventKind::kSoakWaiting, t_s, soak_why_);
  }
  return false;
}

void Sequencer::FeedRate(const StillSample& s) {
  const NoiseProfile& profile = detector_->profile();
  if (!profile.sigma[kTriadGyr]) {
    Reject(s.t_s(), "a rate segment needs the gyro, and this device sends none");
    return;
  }
  if (!rate_) {
    rate_ = std::make_unique<RateSteadiness>(detector_->window(), *profile.sigma[kTriadGyr],
                                             pose_.rate_radps, options_.rate_steady);
  }
  StillSample evicted;
  bool has_evicted = false;
  const bool steady = rate_->Push(s, &evicted, &has_evicted);
  if (state_ == State::kWaiting) {
    if (steady && has_evicted && rate_->steady_run() >= required_run_ - detector_->window() &&
        evicted.t_host_ns > t_announce_ns_) {
      StartCollecting(evicted);
    }
    return;
  }
  if (!steady) {
    Reject(s.t_s(), fmt::format("the rate was not steady after {:.2f} of {:.2f} s: {}",
                                static_cast<double>(counts_.used + counts_.bad()) / profile.rate_hz,
                                static_cast<double>(needed_) / profile.rate_hz, rate_->finding()));
    return;
  }
  if (has_evicted) {
    Commit(evicted);
    if (counts_.used + counts_.bad() >= needed_) Complete(s.t_s());
  }
}

void Sequencer::StartCollecting(const StillSample& first) {
  for (auto& a : acc_) a.Reset();
  for (auto& a : first_half_) a.Reset();
  temp_sum_ = temp_sum2_ = 0;
  temp_n_ = 0;
  counts_ = SampleCounts{};
  needed_ = std::max<std::int64_t>(
      2, static_cast<std::int64_t>(std::ceil(dwell_s_ * detector_->profile().rate_hz - 1e-9)));
  if (rate_mode_) {
    // Whole revolutions at the announced rate, at least the dwell: the rotating components of
    // gravity and the Earth's rate then average out (TablePose::MeanC_p_q).
    const double turn_s = 2 * M_PI / std::abs(pose_.rate_radps);
    const double turns = std::max(1.0, std::ceil(dwell_s_ / turn_s - 1e-9));
    needed_ =
        std::max<std::int64_t>(2, std::llround(turns * turn_s * detector_->profile().rate_hz));
  }
  free_max_needed_ = std::max<std::int64_t>(
      needed_, static_cast<std::int64_t>(
                   std::ceil(options_.free_max_dwell_s * detector_->profile().rate_hz - 1e-9)));
  next_progress_ = static_cast<std::int64_t>(std::ceil(options_.progress_step * needed_));
  t_first_ns_ = first.t_host_ns;
  t_first_sensor_s_ = first.t_sensor_s;
  state_ = State::kCollecting;
  // The move from the last captured pose ends at this dwell's first sample (the last one added):
  // its samples are the record's, and their white noise must not count twice.
  if (!rate_mode_) moves_.End(pose_);
  Emit(SequencerEventKind::kCollecting, first.t_s(),
       fmt::format("still; collecting {} samples", needed_));
  // What was lost or left out before the first sample belongs to before the window.
  StillSample head = first;
  head.lost_before = head.flagged_before = head.outliers_before = 0;
  Commit(head);
}

void Sequencer::Commit(const StillSample& s) {
  ++counts_.used;
  ++totals_.used;
  counts_.lost += s.lost_before;
  counts_.flagged += s.flagged_before;
  counts_.outliers += s.outliers_before;
  for (int t = 0; t < 3; ++t) {
    // Only triads the detector checks: an unchecked one could carry a spike into the record. A
    // rate segment's record holds the gyro only (the others are not stationary).
    if (rate_mode_ && t != kTriadGyr) continue;
    if (s.has(t) && detector_->profile().sigma[t]) {
      acc_[t].Add(s.v[t]);
      if (2 * (counts_.used + counts_.bad()) <= needed_) first_half_[t].Add(s.v[t]);
    }
  }
  if (std::isfinite(s.temp_c)) {
    // Sums about the first sample's temperature: the spread keeps its digits at any level.
    if (temp_n_ == 0) temp_ref_ = temp_min_ = temp_max_ = s.temp_c;
    temp_min_ = std::min(temp_min_, s.temp_c);
    temp_max_ = std::max(temp_max_, s.temp_c);
    temp_sum_ += s.temp_c - temp_ref_;
    temp_sum2_ += (s.temp_c - temp_ref_) * (s.temp_c - temp_ref_);
    ++temp_n_;
  }
  t_last_ns_ = s.t_host_ns;
  t_last_sensor_s_ = s.t_sensor_s;
  last_committed_ = s;
  if (counts_.used + counts_.bad() >= next_progress_ && counts_.used + counts_.bad() < needed_) {
    Emit(SequencerEventKind::kProgress, s.t_s());
    while (next_progress_ <= counts_.used + counts_.bad()) {
      next_progress_ += std::max<std::int64_t>(
          1, static_cast<std::int64_t>(std::ceil(options_.progress_step * needed_)));
    }
  }
}

void Sequencer::CheckTimeout(std::int64_t now_ns) {
  // A stream that stops during the dwell: nothing will complete the pose. A gap between samples
  // is an interruption (Accept, by sending times); this is for a stream that stops for good, so
  // it goes by when the last sample was read, with an allowance for the daemon's own stalls: a
  // tick can run after a stall before the bytes that came meanwhile are read (0.6 s stalls in
  // CI; a replay ticks at every record, elsewhere than the live 50 ms ticks fell).
  if (state_ == State::kCollecting && last_read_ns_ &&
      static_cast<double>(now_ns - *last_read_ns_) * 1e-9 >
          options_.stillness.window_s + kReadStallAllowanceS) {
    Interrupt(static_cast<double>(now_ns) * 1e-9,
              fmt::format("the stream stopped during the dwell (nothing read for {:.2f} s)",
                          static_cast<double>(now_ns - *last_read_ns_) * 1e-9));
    return;
  }
  if (state_ != State::kWaiting || !announced_) return;
  const double waited = (static_cast<double>(now_ns) - static_cast<double>(t_announce_ns_)) * 1e-9;
  if (soak_ && !soak_why_.empty()) {
    // Waiting for the chamber, not for stillness: the soak's own timeout.
    if (waited <= soak_->timeout_s) return;
    Reject(static_cast<double>(now_ns) * 1e-9,
           fmt::format("the soak did not settle within {:.0f} s of the announcement; {}",
                       soak_->timeout_s, soak_why_));
    return;
  }
  if (waited <= options_.still_timeout_s) return;
  std::string why;
  const double t_announce_s = static_cast<double>(t_announce_ns_) * 1e-9;
  if (!detector_) {
    why = fmt::format("the sensor noise is not known yet ({})",
                      last_noise_failure_.empty() ? "still measuring" : last_noise_failure_);
  } else if (!last_host_ns_ || *last_host_ns_ < t_announce_ns_) {
    why = "no samples arrived";
  } else if (rate_mode_ && rate_ && !rate_->finding().empty()) {
    why = "the rate was not steady: " + rate_->finding();
  } else if (last_motion_t_s_ >= t_announce_s) {
    why = fmt::format("last not-still window at t = {:.2f} s: {}", last_motion_t_s_,
                      last_motion_.Describe());
  } else {
    why = "the stillness window did not fill";
  }
  Reject(static_cast<double>(now_ns) * 1e-9,
         fmt::format("not {} within {:.1f} s of the announcement; {}",
                     rate_mode_ ? "at a steady rate" : "still", options_.still_timeout_s, why));
}

void Sequencer::Tick(std::int64_t now_ns) { CheckTimeout(now_ns); }

void Sequencer::Finish(std::int64_t now_ns) {
  const double t_s = static_cast<double>(now_ns) * 1e-9;
  // Free mode: a segment still at the end, at least the dwell long, is an interval (with the move
  // that led to it, before the move in progress is dropped).
  if (free_ && state_ == State::kCollecting && counts_.used + counts_.bad() >= needed_) {
    Complete(t_s);
  }
  moves_.Abort("");  // the input ended: a move in progress leads nowhere
  if (jumped_) {
    // No successor to vouch for its jump.
    ++pending_flagged_;
    ++totals_.flagged;
    if (excluded_) excluded_(*jumped_, "corrupt counter");
    jumped_.reset();
  }
  if (held_) {
    ++pending_outliers_;
    ++totals_.outliers;
    if (excluded_) excluded_(*held_, "outlier");
    held_.reset();
  }
  if (!scheduled()) {
    if (busy()) {
      Reject(t_s, state_ == State::kCollecting
                      ? fmt::format("the input ended during the dwell ({} of {} samples)",
                                    counts_.used + counts_.bad(), needed_)
                      : "the input ended before the sensor was still");
    }
    return;
  }
  if (state_ == State::kCollecting) {
    SkipSegment(t_s, fmt::format("the input ended during the dwell ({} of {} samples)",
                                 counts_.used + counts_.bad(), needed_));
  }
  const auto total = schedule_.size();
  std::string why;
  if (free_) {
    why = fmt::format(
        "free mode: {} intervals captured, {} still segments skipped (shorter than the {:.2f} s "
        "dwell, or not still enough)",
        next_scheduled_, skipped_segments_, options_.dwell_s);
  } else if (next_scheduled_ >= total) {
    why = fmt::format(
        "all {} scheduled poses captured; {} still segments skipped, {} further "
        "still segments after the last pose",
        total, skipped_segments_, extra_segments_);
  } else {
    why = fmt::format(
        "{} of {} scheduled poses captured ({} still segments skipped): the stream has fewer "
        "usable still segments than the schedule has poses",
        next_scheduled_, total, skipped_segments_);
  }
  const int keep = index_;
  const TablePose keep_pose = pose_;
  index_ = -1;
  pose_ = TablePose{};
  Emit(SequencerEventKind::kScheduleEnd, t_s, why);
  index_ = keep;
  pose_ = keep_pose;
  state_ = State::kScheduleDone;
}

}  // namespace turncal
