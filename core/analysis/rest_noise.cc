#include "core/analysis/rest_noise.h"

#include <algorithm>
#include <map>
#include <tuple>

namespace turncal {

namespace {

constexpr std::size_t kPeriodIntervals = 4096;

// The log-log slope of the Allan variance at tau: the fitted model's, or the measured points'
// about it when there is no fit.
double AvarSlope(const NoiseFit& fit, const std::vector<RestNoisePoint>& points, std::size_t i) {
  if (fit.ok) {
    const double t = points[i].tau_s, k = 1.2;
    const double hi = fit.Adev(t * k), lo = fit.Adev(t / k);
    if (hi > 0 && lo > 0) return 2.0 * (std::log(hi) - std::log(lo)) / (2.0 * std::log(k));
  }
  const std::size_t a = i > 0 ? i - 1 : i, b = i + 1 < points.size() ? i + 1 : i;
  if (a == b || !(points[a].adev > 0) || !(points[b].adev > 0)) return -1.0;
  return 2.0 * std::log(points[b].adev / points[a].adev) /
         std::log(points[b].tau_s / points[a].tau_s);
}

VarianceInterval DeviationInterval(double deviation, double edf, double confidence) {
  const VarianceInterval v = ChiSquaredInterval(deviation * deviation, edf, confidence);
  return {std::sqrt(v.low), std::sqrt(v.high)};
}

}  // namespace

// The Allan deviation, its intervals, the Hadamard deviation and the noise fit of every axis of
// every triad with at least 16 intervals in [from, to] (the median of the first intervals as the
// sample period).
std::vector<RestNoiseAxis> AnalyseRestNoise(const RestNoise& noise) {
  std::vector<RestNoiseAxis> results;
  // The axes of a triad share cluster sizes and mostly noise types: each edf once.
  std::map<std::tuple<int, int, std::int64_t, std::int64_t, std::int64_t>, double> edfs;
  auto edf = [&edfs](int alpha, int d, std::int64_t m, std::int64_t stride, std::int64_t n) {
    const auto key = std::make_tuple(alpha, d, m, stride, n);
    auto it = edfs.find(key);
    if (it == edfs.end()) it = edfs.emplace(key, OverlappingEdf(alpha, d, m, stride, n)).first;
    return it->second;
  };
  for (const RestTriad* triad : {&noise.acc, &noise.gyr, &noise.mag}) {
    const double dt = triad->period_s();
    const std::int64_t n = triad->samples();
    if (n < 17 || !(dt > 0)) continue;
    const std::vector<StreamingAllanPoint> points = triad->allan().Points();
    for (int axis = 0; axis < 3; ++axis) {
      RestNoiseAxis r;
      r.triad = triad->name();
      r.axis = axis;
      r.samples = static_cast<std::size_t>(n);
      r.rate_hz = 1.0 / dt;
      r.gaps = triad->gaps();
      for (const StreamingAllanPoint& p : points) {
        RestNoisePoint o;
        o.m = p.m;
        o.stride = p.stride;
        o.tau_s = static_cast<double>(p.m) * dt;
        o.adev = std::sqrt(p.avar[static_cast<std::size_t>(axis)]);
        if (!p.hvar.empty()) o.hdev = std::sqrt(p.hvar[static_cast<std::size_t>(axis)]);
        r.points.push_back(o);
        if (9 * p.m <= n) {
          r.fitted.push_back({o.tau_s, o.adev, static_cast<double>(n) / static_cast<double>(p.m)});
        }
      }
      r.fit = FitNoiseModel(r.fitted);
      std::vector<IeeeAvarPoint> avars;
      for (const StreamingAllanPoint& p : points) {
        avars.push_back({p.m, p.avar[static_cast<std::size_t>(axis)]});
      }
      r.ieee = FitIeeeNoise(avars, dt, n);
      // The warm-up transient, below the floor of the Allan deviation.
      double floor = INFINITY;
      for (const RestNoisePoint& o : r.points)
        if (9 * o.m <= n) floor = std::min(floor, o.adev);
      std::vector<double> bin_t, bin_mean;
      triad->bins().Series(axis, &bin_t, &bin_mean);
      const double bin_s = triad->bins().bin_s();
      const BinNoiseModel bin_noise = BinNoiseFromIeee(r.ieee, bin_s, triad->span_s());
      r.warm_up = FitWarmUp(bin_t, bin_mean, bin_s, std::isfinite(floor) ? floor : 0.0,
                            r.ieee.ok ? &bin_noise : nullptr);
      for (std::size_t i = 0; i < r.points.size(); ++i) {
        RestNoisePoint& o = r.points[i];
        o.alpha = NoiseTypeOfSlope(AvarSlope(r.fit, r.points, i));
        o.edf = edf(o.alpha, 2, o.m, o.stride, n);
        o.ci68 = DeviationInterval(o.adev, o.edf, 0.683);
        o.ci95 = DeviationInterval(o.adev, o.edf, 0.95);
        if (std::isfinite(o.hdev)) {
          o.hedf = edf(o.alpha, 3, o.m, o.stride, n);
          o.hci68 = DeviationInterval(o.hdev, o.hedf, 0.683);
          o.hci95 = DeviationInterval(o.hdev, o.hedf, 0.95);
        }
      }
      results.push_back(std::move(r));
    }
  }
  return results;
}

void RestTriad::Add(double t_s, const Eigen::Vector3d& v, double from_s, double to_s) {
  if (!started_) t_first_ = t_s, started_ = true;
  const double t = t_s - t_first_;
  if (!(t >= from_s && t <= to_s) || !v.allFinite()) return;
  if (samples() == 0) {
    t_kept_ = t_s;
  } else if (first_intervals_.size() < kPeriodIntervals) {
    first_intervals_.push_back(t_s - t_last_);
  } else if (t_s - t_last_ > 1.5 * period_s()) {
    ++late_gaps_;
  }
  t_last_ = t_s;
  allan_.Add(v.data());
  bins_.Add(t, v);
}

double RestTriad::period_s() const {
  if (period_s_ > 0) return period_s_;
  if (first_intervals_.empty()) return 0.0;
  std::vector<double> sorted = first_intervals_;
  std::nth_element(sorted.begin(), sorted.begin() + static_cast<long>(sorted.size() / 2),
                   sorted.end());
  const double median = sorted[sorted.size() / 2];
  if (first_intervals_.size() >= kPeriodIntervals) period_s_ = median;
  return median;
}

std::int64_t RestTriad::gaps() const {
  const double period = period_s();
  std::int64_t gaps = late_gaps_;
  for (double dt : first_intervals_) gaps += dt > 1.5 * period;
  return gaps;
}

const char* RestNoiseUnit(const std::string& triad) {
  return triad == "acc" ? "m/s^2" : triad == "gyr" ? "rad/s" : "G";
}

}  // namespace turncal
