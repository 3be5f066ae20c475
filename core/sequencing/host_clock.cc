#include "core/sequencing/host_clock.h"

#include <algorithm>
#include <cmath>
#include <vector>

namespace turncal {
namespace {

constexpr std::int64_t kStretchNs = 250'000'000;     // one point per 0.25 s of host time
constexpr std::int64_t kWindowNs = 32'000'000'000;   // over the last 32 s
constexpr std::int64_t kMinApartNs = 2'000'000'000;  // slopes between points >= 2 s apart
constexpr std::size_t kMinSlopes = 8;                // (the first after 3.25 s)
constexpr double kRealTime = 0.01;                   // a rate within 1 % of 1 is real time
constexpr double kNewRate = 1e-4;  // a measured rate this far from the one in use replaces it

}  // namespace

HostClock::HostClock(double max_drift) : max_drift_(max_drift) {
  static_assert(kMaxStretches >= kWindowNs / kStretchNs + 2);
  stretches_.resize(kMaxStretches);
  slopes_.reserve(kMaxStretches * (kMaxStretches - 1) / 2);
}

void HostClock::MeasureRate(const Point& p) {
  // The offset of a point under the rate in use: the smallest marks the promptest read.
  auto offset = [&](const Point& q) {
    return static_cast<double>(q.host_ns - p.host_ns) * 1e-9 - rate_ * (q.device_s - p.device_s);
  };
  if (open_ && p.host_ns - open_start_ns_ < kStretchNs) {
    if (offset(p) < offset(*open_)) open_ = p;
    return;
  }
  if (open_) {
    if (stretch_count_ == kMaxStretches) {  // (the window ends first unless reads stop)
      stretch_first_ = (stretch_first_ + 1) % kMaxStretches;
      --stretch_count_;
    }
    stretches_[(stretch_first_ + stretch_count_++) % kMaxStretches] = *open_;
  }
  open_ = p;
  open_start_ns_ = p.host_ns;
  auto stretch = [&](std::size_t i) -> const Point& {
    return stretches_[(stretch_first_ + i) % kMaxStretches];
  };
  while (stretch_count_ > 0 && p.host_ns - stretch(0).host_ns > kWindowNs) {
    stretch_first_ = (stretch_first_ + 1) % kMaxStretches;
    --stretch_count_;
  }
  // (Fixed storage: the clock allocates nothing per sample or per stretch.)
  slopes_.clear();
  for (std::size_t i = 0; i < stretch_count_; ++i) {
    for (std::size_t j = i + 1; j < stretch_count_; ++j) {
      const Point& a = stretch(i);
      const Point& b = stretch(j);
      if (b.host_ns - a.host_ns < kMinApartNs || !(b.device_s > a.device_s)) continue;
      slopes_.push_back(static_cast<double>(b.host_ns - a.host_ns) * 1e-9 /
                        (b.device_s - a.device_s));
    }
  }
  if (slopes_.size() < kMinSlopes) return;
  auto mid = slopes_.begin() + static_cast<long>(slopes_.size() / 2);
  std::nth_element(slopes_.begin(), mid, slopes_.end());
  const double measured = std::abs(*mid - 1.0) <= kRealTime ? 1.0 : *mid;
  if (std::abs(measured / rate_ - 1.0) <= kNewRate) return;
  rate_ = measured;
  // The offset estimate was under the old rate: its sample's offset under the new one.
  if (key_min_) key_min_ = Key(min_point_);
}

double HostClock::Key(const Point& p) const {
  // Relative to the epoch, in host seconds: the sample's offset, less its drift allowance.
  const double dev_s = (p.device_s - epoch_device_s_) * rate_;
  const double offset = static_cast<double>(p.host_ns - epoch_host_ns_) * 1e-9 - dev_s;
  return offset - max_drift_ * dev_s;
}

std::int64_t HostClock::Map(std::int64_t t_host_ns, std::optional<double> t_device_s) {
  if (!t_device_s || !std::isfinite(*t_device_s)) {
    last_mapped_ns_ = std::max(last_mapped_ns_.value_or(t_host_ns), t_host_ns);
    return t_host_ns;
  }
  const double host_step_s = static_cast<double>(t_host_ns - last_host_ns_) * 1e-9;
  const bool backwards = last_device_s_ && *t_device_s < *last_device_s_;
  if (backwards) {  // another clock (a restart): nothing measured on the old one applies
    stretch_count_ = 0;
    open_.reset();
  }
  if (!backwards) MeasureRate({*t_device_s, t_host_ns});
  const bool reset = !key_min_ || !last_device_s_ || backwards ||
                     (*t_device_s - *last_device_s_) * rate_ > host_step_s + 1.0;
  if (reset) {
    if (key_min_) ++resets_;
    epoch_host_ns_ = t_host_ns;
    epoch_device_s_ = *t_device_s;
    key_min_.reset();
  }
  last_device_s_ = t_device_s;
  last_host_ns_ = t_host_ns;
  const Point p{*t_device_s, t_host_ns};
  const double key = Key(p);
  if (!key_min_ || key < *key_min_) {
    key_min_ = key;
    min_point_ = p;
  }
  const double dev_s = (*t_device_s - epoch_device_s_) * rate_;
  const double mapped_offset = *key_min_ + max_drift_ * dev_s;  // <= offset
  auto mapped =
      epoch_host_ns_ + static_cast<std::int64_t>(std::llround((dev_s + mapped_offset) * 1e9));
  mapped = std::min(mapped, t_host_ns);
  if (last_mapped_ns_ && !reset) mapped = std::max(mapped, std::min(*last_mapped_ns_, t_host_ns));
  last_mapped_ns_ = mapped;
  return mapped;
}

}  // namespace turncal
