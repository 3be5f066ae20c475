#include "core/sequencing/rate_steady.h"

#include <fmt/format.h>

#include <cmath>

#include "core/frames/units.h"

namespace turncal {

bool RateSteadyOptions::IsValid(std::string* error) const {
  if (!(ripple >= 0 && ripple < 0.1) || !(z > 0 && z <= 20)) {
    if (error) *error = "rate ripple must be in [0, 0.1) and its z in (0, 20]";
    return false;
  }
  return true;
}

RateSteadiness::RateSteadiness(std::int64_t window, const Eigen::Vector3d& sigma, double rate_radps,
                               const RateSteadyOptions& options)
    : window_(std::max<std::int64_t>(window, 4)),
      sigma_(sigma),
      rate_radps_(rate_radps),
      options_(options),
      ring_(static_cast<std::size_t>(window_)) {}

bool RateSteadiness::Push(const StillSample& s, StillSample* evicted, bool* has_evicted) {
  *has_evicted = count_ >= window_;
  if (*has_evicted) {
    *evicted = ring_[next_];
    sum_ -= evicted->v[kTriadGyr];
  }
  ring_[next_] = s;
  sum_ += s.v[kTriadGyr];
  next_ = (next_ + 1) % ring_.size();
  if (count_ < window_) ++count_;
  if (count_ < window_ || !Steady()) {
    run_ = 0;
    return false;
  }
  ++run_;
  return true;
}

bool RateSteadiness::IsOutlier(const StillSample& s) const {
  if (count_ < window_) return false;
  const Eigen::Vector3d mean = sum_ / static_cast<double>(window_);
  const double ripple = options_.ripple * std::abs(rate_radps_);
  for (int a = 0; a < 3; ++a) {
    const double x = s.v[kTriadGyr][a];
    if (!std::isfinite(x) || std::abs(x - mean[a]) > 8 * sigma_[a] + 2 * ripple) return true;
  }
  return false;
}

bool RateSteadiness::Steady() {
  // The window in time order starts at next_.
  const auto w = static_cast<std::size_t>(window_);
  const std::size_t half = w / 2;
  Eigen::Vector3d mean1 = Eigen::Vector3d::Zero(), mean2 = Eigen::Vector3d::Zero();
  for (std::size_t k = 0; k < w; ++k) {
    const Eigen::Vector3d& g = ring_[(next_ + k) % w].v[kTriadGyr];
    (k < half ? mean1 : mean2) += g;
  }
  mean1 /= static_cast<double>(half);
  mean2 /= static_cast<double>(w - half);
  const Eigen::Vector3d mean =
      (mean1 * static_cast<double>(half) + mean2 * static_cast<double>(w - half)) /
      static_cast<double>(w);
  Eigen::Vector3d var = Eigen::Vector3d::Zero();
  for (std::size_t k = 0; k < w; ++k) {
    var += (ring_[(next_ + k) % w].v[kTriadGyr] - mean).cwiseAbs2();
  }
  var /= static_cast<double>(w - 1);
  const double ripple = options_.ripple * std::abs(rate_radps_);
  const double z = options_.z;
  const double n = static_cast<double>(w);
  for (int a = 0; a < 3; ++a) {
    const double white = sigma_[a] * sigma_[a];
    // The chi^2 quantile of the sample variance (Wilson-Hilferty) at z normal deviates.
    const double k = n - 1;
    const double chi2_over_k = std::pow(1 - 2 / (9 * k) + z * std::sqrt(2 / (9 * k)), 3);
    const double spread_limit = white * chi2_over_k + ripple * ripple / 2;
    if (!(var[a] <= spread_limit)) {
      finding_ =
          fmt::format("gyro {} spread {:.3g} deg/s above the steady limit {:.3g} deg/s", "xyz"[a],
                      std::sqrt(var[a]) * kDegPerRad, std::sqrt(spread_limit) * kDegPerRad);
      return false;
    }
    const double halves_limit = z * sigma_[a] * std::sqrt(4 / n) + 2 * ripple;
    if (!(std::abs(mean2[a] - mean1[a]) <= halves_limit)) {
      finding_ = fmt::format(
          "gyro {} rate changed {:.3g} deg/s within the window (steady limit {:.3g} deg/s)",
          "xyz"[a], std::abs(mean2[a] - mean1[a]) * kDegPerRad, halves_limit * kDegPerRad);
      return false;
    }
  }
  const double magnitude = mean.norm();
  const double want = std::abs(rate_radps_);
  if (!(std::abs(magnitude - want) <= 0.05 * want + 2 * kRadPerDeg)) {
    finding_ = fmt::format("the gyro reads {:.3f} deg/s, the announced rate is {:.3f} deg/s",
                           magnitude * kDegPerRad, want * kDegPerRad);
    return false;
  }
  finding_.clear();
  return true;
}

}  // namespace turncal
