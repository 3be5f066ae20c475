// The sequencer's intake (core/sequencing/sequencer.h): each sample's counter or clock against
// the last one's (lost samples, corrupted counters, interruptions), its host time of sending
// (HostClock) and sensor time, flags, the start-up noise measurement, the moves' queue and the
// isolated-outlier test, before the stillness detector (Feed, in sequencer.cc).
#include <fmt/format.h>

#include <algorithm>
#include <cmath>

#include "core/sequencing/sequencer.h"

namespace turncal {
namespace {

constexpr std::uint32_t kBadFlags =
    kAccSaturated | kGyrSaturated | kMagSaturated | kStatusError | kClipping;
// A device-clock jump this large or larger counts no lost samples (a clock reset, not a gap).
constexpr double kMaxSteps = 1e7;

}  // namespace

void Sequencer::Push(const Sample& sample) { Push(ToStillSample(sample)); }

std::optional<std::int64_t> Sequencer::StepsAhead(const StillSample& s) const {
  if (s.counter) {
    if (!last_counter_) return std::nullopt;
    // 16 bits wrap: -32768..32767 periods.
    return static_cast<std::int16_t>(static_cast<std::uint16_t>(*s.counter - *last_counter_));
  }
  const NoiseProfile* p = noise();
  if (!s.t_device_s || !last_device_s_ || !p || !p->device_period_s || !(*p->device_period_s > 0)) {
    return std::nullopt;
  }
  const double k = std::round((*s.t_device_s - *last_device_s_) / *p->device_period_s);
  if (std::isnan(k)) return std::nullopt;
  return static_cast<std::int64_t>(std::clamp(k, -kMaxSteps, kMaxSteps));
}

std::uint32_t Sequencer::CountLost(const StillSample& s) {
  const std::optional<std::int64_t> steps = StepsAhead(s);
  if (s.counter) last_counter_ = s.counter;
  if (s.t_device_s) last_device_s_ = s.t_device_s;
  return steps && *steps > 1 && *steps < kMaxSteps ? static_cast<std::uint32_t>(*steps - 1) : 0u;
}

void Sequencer::Push(StillSample s) {
  // A sample whose counter or device clock breaks the sequence (backwards, or more samples ahead
  // than half a window: an interruption) waits for its successor. A successor that continues the
  // old sequence shows the jump was a corrupted counter or time stamp (a bit error the frame's
  // checksum missed, ~1 in 16 double errors for Xbus's 8-bit sum): that sample is dropped
  // (counted as flagged), not taken for an interruption. Otherwise the jump was real.
  const auto plausible = [this](std::optional<std::int64_t> steps) {
    return !steps ||
           (*steps >= 1 && *steps - 1 <= static_cast<std::int64_t>(detector_->window() / 2));
  };
  if (jumped_) {
    const StillSample jumped = *jumped_;
    jumped_.reset();
    const std::optional<std::int64_t> steps = StepsAhead(s);
    if (steps && plausible(steps)) {
      ++pending_flagged_;
      ++move_flagged_;  // its interval is missing from a move, uncounted: the move is dropped
      ++totals_.flagged;
      if (excluded_) excluded_(jumped, "corrupt counter");
      // It stood for the sample after the last one (unless `s` is that one): not lost.
      if (*steps > 1) {
        if (last_counter_) ++*last_counter_;
        if (last_device_s_ && noise()->device_period_s)
          *last_device_s_ += *noise()->device_period_s;
      }
    } else {
      Accept(jumped);
    }
  }
  if (detector_ && !plausible(StepsAhead(s))) {
    jumped_ = s;
    return;
  }
  Accept(s);
}

double Sequencer::SensorTime(const StillSample& s) {
  const double host = s.t_s();
  double t;
  if (s.t_device_s && std::isfinite(*s.t_device_s)) {
    const double device = *s.t_device_s;
    if (sensor_last_device_s_) {
      const double d_device = device - *sensor_last_device_s_;
      const double d_host = std::max(host - sensor_last_host_s_, 0.0);
      // Backwards, or far ahead of what the host saw pass (a reset or a corrupt time stamp that
      // was real enough to be accepted): continue from the last sensor time by the host's gap.
      if (!(d_device >= 0) || d_device > 2 * d_host + 10.0) {
        sensor_offset_s_ = *sensor_last_s_ + d_host - device;
      }
    } else if (sensor_last_s_) {
      // The first device time after samples without one.
      sensor_offset_s_ = *sensor_last_s_ + std::max(host - sensor_last_host_s_, 0.0) - device;
    }
    t = device + sensor_offset_s_;
    sensor_last_device_s_ = device;
  } else {
    t = sensor_last_s_ ? *sensor_last_s_ + std::max(host - sensor_last_host_s_, 0.0) : host;
    sensor_last_device_s_.reset();
  }
  sensor_last_s_ = t;
  sensor_last_host_s_ = host;
  return t;
}

void Sequencer::Accept(StillSample s) {
  last_read_ns_ = s.t_host_ns;
  // From here on a sample's time is when its device sent it, on the host clock (HostClock): a
  // backlog read at once after an announcement belongs before it.
  s.t_host_ns = clock_.Map(s.t_host_ns, s.t_device_s);
  s.t_sensor_s = SensorTime(s);
  CheckTimeout(s.t_host_ns);
  const double t_s = s.t_s();
  const std::uint32_t lost = CountLost(s);
  const std::optional<std::int64_t> previous_host = last_host_ns_;
  last_host_ns_ = s.t_host_ns;
  totals_.lost += lost;
  // An interruption: many samples lost, or none received for longer than a window. The window
  // cannot vouch for what happened in between. Checked before anything may drop this sample.
  if (detector_) {
    const double host_gap_s =
        previous_host ? static_cast<double>(s.t_host_ns - *previous_host) * 1e-9 : 0.0;
    const auto half = static_cast<std::uint32_t>(detector_->window() / 2);
    if (lost > half || host_gap_s > options_.stillness.window_s) {
      Interrupt(t_s, lost > half
                         ? fmt::format("the stream was interrupted ({} samples lost)", lost)
                         : fmt::format("the stream was interrupted (no sample for {:.2f} s)",
                                       host_gap_s));
    } else {
      // Carried with the sample (a held outlier may go in before it: its gap is after that one).
      s.lost_before = lost;
    }
  }
  bool finite = true;
  for (int t = 0; t < 3; ++t) {
    if (s.has(t) && !s.v[t].allFinite()) finite = false;
  }
  s.seq = ++accepted_;
  if ((s.flags & kBadFlags) || !finite) {
    ++move_flagged_;
    move_lost_ += s.lost_before;
    pending_lost_ += s.lost_before;
    ++pending_flagged_;
    ++totals_.flagged;
    if (excluded_) excluded_(s, finite ? "flagged" : "non-finite");
    return;
  }
  if (!detector_) {
    if (options_.noise) {
      // A configured profile: the triads this device sends (a datasheet class names mag too).
      NoiseProfile profile = *options_.noise;
      for (int t = 0; t < 3; ++t) {
        if (!s.has(t)) profile.sigma[t].reset();
      }
      std::string error;
      if (!profile.IsValid(&error)) {
        pending_lost_ += s.lost_before;
        ++pending_flagged_;
        ++totals_.flagged;
        if (excluded_) excluded_(s, "incomplete");
        return;
      }
      StartDetector(profile, t_s);
    } else {
      pending_lost_ += s.lost_before;  // the noise meter takes the sample
      switch (meter_.Add(s)) {
        case NoiseMeter::Status::kCollecting:
          return;
        case NoiseMeter::Status::kMeasured:
          StartDetector(meter_.profile(), t_s);
          return;
        case NoiseMeter::Status::kRejected: {
          last_noise_failure_ = meter_.failure();
          const int keep = index_;
          index_ = -1;
          Emit(SequencerEventKind::kNoiseRetry, t_s, meter_.failure());
          index_ = keep;
          meter_.Restart();
          meter_.Add(s);
          return;
        }
      }
    }
  }
  for (int t = 0; t < 3; ++t) {
    if (detector_->profile().sigma[t] && !s.has(t)) {
      ++move_flagged_;
      move_lost_ += s.lost_before;
      pending_lost_ += s.lost_before;
      ++pending_flagged_;
      ++totals_.flagged;
      if (excluded_) excluded_(s, "incomplete");
      return;
    }
  }
  // The moves integrate every sample, outliers too (in motion the window's median lags behind the
  // rate, and a sample at the edge of a move that the outlier test drops is not a random one):
  // they take the samples from their own queue, in step with the detector's delayed stream.
  if (!move_ring_.empty()) {
    StillSample q = s;
    q.lost_before += move_lost_;
    q.flagged_before = move_flagged_;
    q.outliers_before = 0;
    move_lost_ = move_flagged_ = 0;
    if (move_size_ == move_ring_.size()) {
      // More than a window of outliers in two windows' span: the oldest sample would be lost to
      // a move, so the move goes.
      moves_.Abort("the moves' queue overflowed");
      move_head_ = (move_head_ + 1) % move_ring_.size();
      --move_size_;
    }
    move_ring_[(move_head_ + move_size_) % move_ring_.size()] = q;
    ++move_size_;
  }
  // Isolated outliers: a sample far from the window's median is held; if the next one is far
  // too, both are real (the table moves) and go in; otherwise the held one is dropped. In a rate
  // segment the gyro alone decides (the other triads turn with the table).
  const bool by_rate =
      rate_mode_ && rate_ && (state_ == State::kWaiting || state_ == State::kCollecting);
  const auto is_outlier = [&](const StillSample& x) {
    return by_rate ? rate_->IsOutlier(x) : detector_->IsOutlier(x);
  };
  if (held_) {
    if (is_outlier(s)) {
      Feed(*held_);
      held_.reset();
      Feed(s);
    } else {
      pending_lost_ += held_->lost_before;
      ++pending_outliers_;
      ++totals_.outliers;
      if (excluded_) excluded_(*held_, "outlier");
      held_.reset();
      Feed(s);
    }
  } else if (is_outlier(s)) {
    held_ = s;
  } else {
    Feed(s);
  }
}

}  // namespace turncal
