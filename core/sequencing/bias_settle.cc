#include "core/sequencing/bias_settle.h"

#include <fmt/format.h>

#include <cmath>

namespace turncal {

namespace {
constexpr double kBinS = 0.1;
constexpr const char* kTriadNames[3] = {"acc", "gyr", "mag"};
constexpr const char* kAxisNames[3] = {"x", "y", "z"};
}  // namespace

void BiasSettleTracker::Add(const StillSample& s, double window_s) {
  const double t = s.t_s();
  if (!std::isfinite(t)) return;
  if (!bins_.empty() && t < bins_.back().t1_s) return;  // time went back: not this window's
  if (bins_.empty() || t >= bins_.back().t0_s + kBinS) {
    bins_.push_back(Bin{});
    bins_.back().t0_s = t;
  }
  Bin& b = bins_.back();
  b.t1_s = t;
  for (int k = 0; k < 3; ++k) {
    if (!s.has(k) || !s.v[static_cast<std::size_t>(k)].allFinite()) continue;
    b.sum[static_cast<std::size_t>(k)] += s.v[static_cast<std::size_t>(k)];
    b.count[static_cast<std::size_t>(k)] += 1.0;
  }
  while (!bins_.empty() && bins_.front().t0_s < t - window_s) bins_.pop_front();
}

double BiasSettleTracker::span_s() const {
  return bins_.empty() ? 0.0 : bins_.back().t1_s - bins_.front().t0_s;
}

bool BiasSettleTracker::Settled(double window_s, const HalvesLimit& limit, std::string* why) const {
  if (span_s() < 0.8 * window_s) {
    if (why) {
      *why = fmt::format(
          "the bias is watched for {:.0f} s of the table at rest before it can be called settled "
          "({:.0f} s so far)",
          window_s, span_s());
    }
    return false;
  }
  const double middle = 0.5 * (bins_.front().t0_s + bins_.back().t1_s);
  std::array<Eigen::Vector3d, 3> first{}, second{};
  std::array<double, 3> n1{0, 0, 0}, n2{0, 0, 0};
  for (int k = 0; k < 3; ++k) first[k].setZero(), second[k].setZero();
  for (const Bin& b : bins_) {
    const bool early = 0.5 * (b.t0_s + b.t1_s) < middle;
    for (std::size_t k = 0; k < 3; ++k) {
      (early ? first : second)[k] += b.sum[k];
      (early ? n1 : n2)[k] += b.count[k];
    }
  }
  // The axis furthest beyond its limit names the reason.
  double worst = 1.0;
  std::string reason;
  for (int k = 0; k < 3; ++k) {
    const auto t = static_cast<std::size_t>(k);
    if (!(n1[t] > 0) || !(n2[t] > 0)) continue;
    const Eigen::Vector3d change = second[t] / n2[t] - first[t] / n1[t];
    for (int a = 0; a < 3; ++a) {
      const double lim = limit ? limit(k, a, n1[t], n2[t]) : 0.0;
      if (!(lim > 0)) continue;
      const double ratio = std::abs(change[a]) / lim;
      if (ratio > worst) {
        worst = ratio;
        reason = fmt::format(
            "the bias still moves: {} {} changed by {:+.2e} between the halves of the last {:.0f} "
            "s "
            "(within {:.2e} when settled)",
            kTriadNames[k], kAxisNames[a], change[a], span_s(), lim);
      }
    }
  }
  if (reason.empty()) return true;
  if (why) *why = reason;
  return false;
}

}  // namespace turncal
