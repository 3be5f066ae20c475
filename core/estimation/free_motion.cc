#include "core/estimation/free_motion.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>

#include "core/models/free_common.h"

namespace turncal {
namespace {

double Median(std::vector<double> v) {
  if (v.empty()) return 0.0;
  const auto mid = v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2);
  std::nth_element(v.begin(), mid, v.end());
  return *mid;
}

// The robust 1 sigma of the points' distance from an algebraic ellipsoid (or sphere) through
// them, in the points' unit; 0 when neither can be fitted.
double ScatterSigma(const std::vector<Eigen::Vector3d>& points) {
  std::vector<double> d;
  if (auto e = free::FitEllipsoid(points)) {
    double radius = 0;
    for (const auto& p : points) radius += (p - e->center).norm();
    radius /= static_cast<double>(points.size());
    for (const auto& p : points) {
      const Eigen::Vector3d x = p - e->center;
      d.push_back((std::sqrt(std::max(0.0, x.dot(e->E * x))) - 1.0) * radius);
    }
  } else if (auto s = free::FitSphere(points)) {
    for (const auto& p : points) d.push_back((p - s->center).norm() - s->radius);
  } else {
    return 0.0;
  }
  const double m = Median(d);
  for (double& v : d) v = std::abs(v - m);
  return 1.4826 * Median(d);
}

}  // namespace

std::string MotionPoints::Summary() const {
  std::string s = fmt::format(
      "magnetometer in motion: {} values taken (of {} samples with the field: {} held repeats "
      "dropped, {} in or next to still intervals",
      points.size(), samples_with_mag, held, in_intervals);
  if (decimated > 0) s += fmt::format(", {} left out to keep at most {}", decimated, points.size());
  s += ")";
  if (period_s > 0) s += fmt::format(" at {:.1f} Hz", 1.0 / period_s);
  if (!points.empty()) {
    s += fmt::format("; noise {:.3g} {:.3g} {:.3g} per sample ({})", sigma.x(), sigma.y(),
                     sigma.z(), noise_source);
  }
  return s;
}

MotionPoints MagnetometerInMotion(const std::vector<Sample>& samples,
                                  const std::vector<FreeInterval>& intervals,
                                  const MotionOptions& options) {
  MotionPoints out;
  // The new values: a sample whose field is not the previous sample's exactly.
  std::vector<const Sample*> fresh;
  const Eigen::Vector3d* previous = nullptr;
  for (const Sample& s : samples) {
    if (!s.mag || !s.mag->allFinite()) continue;
    ++out.samples_with_mag;
    if (previous && *previous == *s.mag) {
      ++out.held;
    } else {
      fresh.push_back(&s);
    }
    previous = &*s.mag;
  }
  if (fresh.size() < 2) return out;
  // The period between new values (the median spacing on the host's clock, or the device's).
  std::vector<double> gaps;
  for (std::size_t i = 1; i < fresh.size(); ++i) {
    const Sample& a = *fresh[i - 1];
    const Sample& b = *fresh[i];
    gaps.push_back(a.t_device_s && b.t_device_s
                       ? *b.t_device_s - *a.t_device_s
                       : static_cast<double>(b.t_host_ns - a.t_host_ns) * 1e-9);
  }
  out.period_s = std::max(Median(gaps), 1e-6);
  // Outside the still intervals, with a margin of two periods on each side.
  std::vector<std::pair<double, double>> still;
  for (const auto& iv : intervals) {
    if (!iv.in_motion) still.emplace_back(iv.t_start_s, iv.t_end_s);
  }
  std::sort(still.begin(), still.end());
  std::vector<const Sample*> moving;
  std::size_t w = 0;
  const double margin = 2 * out.period_s;
  for (const Sample* s : fresh) {
    const double t = static_cast<double>(s->t_host_ns) * 1e-9;
    while (w < still.size() && still[w].second + margin < t) ++w;
    if (w < still.size() && t >= still[w].first - margin) {
      ++out.in_intervals;
      continue;
    }
    moving.push_back(s);
  }
  // At most max_points, evenly spread over the new values in motion.
  const std::size_t max_points = static_cast<std::size_t>(std::max(options.max_points, 1));
  std::vector<const Sample*> kept;
  if (moving.size() <= max_points) {
    kept = moving;
  } else {
    for (std::size_t j = 0; j < max_points; ++j)
      kept.push_back(moving[j * moving.size() / max_points]);
  }
  out.decimated = static_cast<std::int64_t>(moving.size() - kept.size());
  if (kept.empty()) return out;

  if (options.mag_sigma) {
    out.sigma = *options.mag_sigma;
    out.noise_source = options.noise_source.empty() ? "given" : options.noise_source;
  } else {
    std::vector<Eigen::Vector3d> values;
    for (const Sample* s : kept) values.push_back(*s->mag);
    out.sigma.setConstant(ScatterSigma(values));
    out.noise_source =
        "the points' scatter about an ellipsoid through them: the chi^2 is no check of the noise";
  }
  const Eigen::Matrix3d covariance = out.sigma.cwiseAbs2().cwiseMax(1e-300).asDiagonal();
  for (const Sample* s : kept) {
    FreeInterval p;
    p.in_motion = true;
    p.t_start_s = static_cast<double>(s->t_host_ns) * 1e-9;
    p.t_end_s = p.t_start_s + out.period_s;
    if (s->t_device_s) {
      p.sensor_t_start_s = *s->t_device_s;
      p.sensor_t_end_s = *s->t_device_s + out.period_s;
    }
    TriadStats m;
    m.mean = *s->mag;
    m.covariance = covariance;
    m.count = 1;
    p.mag = m;
    p.temp_c = s->temp_c;
    out.points.push_back(std::move(p));
  }
  return out;
}

FreeCollected CollectFree(const std::vector<Sample>& samples, const SequencerOptions& options,
                          const MotionOptions* motion) {
  FreeCollected out;
  FreeIntervalCollector collector(options);
  for (const Sample& s : samples) collector.Push(s);
  out.found = collector.Finish(samples.empty() ? 0 : samples.back().t_host_ns);
  out.data = out.found.intervals;
  const bool has_mag = std::any_of(samples.begin(), samples.end(),
                                   [](const Sample& s) { return s.mag.has_value(); });
  if (motion && has_mag) {
    MotionOptions mo = *motion;
    if (!mo.mag_sigma && out.found.noise && out.found.noise->sigma[kTriadMag]) {
      mo.mag_sigma = *out.found.noise->sigma[kTriadMag];
      mo.noise_source = out.found.noise->source;
    }
    out.motion = MagnetometerInMotion(samples, out.found.intervals, mo);
    out.data.insert(out.data.end(), out.motion->points.begin(), out.motion->points.end());
  }
  return out;
}

}  // namespace turncal
