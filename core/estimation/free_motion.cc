#include "core/estimation/free_motion.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <tuple>

#include "core/models/free_common.h"

namespace turncal {

double MedianOf(std::vector<double> v) {
  if (v.empty()) return 0.0;
  const auto mid = v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2);
  std::nth_element(v.begin(), mid, v.end());
  return *mid;
}

namespace {

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
  const double m = MedianOf(d);
  for (double& v : d) v = std::abs(v - m);
  return 1.4826 * MedianOf(d);
}

}  // namespace

bool MotionOptions::TakeNoise(const NoiseProfile& profile) {
  if (!profile.sigma[kTriadMag]) return false;
  mag_sigma = *profile.sigma[kTriadMag];
  mag_sigma_dof = profile.TriadDof(kTriadMag);
  mag_sigma_rate_hz = profile.rate_hz;
  noise_source = profile.source;
  mag_sigma_measured_host_s = profile.measured_host_s;
  return true;
}

std::string MotionPoints::Summary() const {
  std::string s = fmt::format(
      "magnetometer in motion: {} values taken (of {} samples with the field: {} held repeats "
      "dropped, {} in or next to still intervals",
      points.size(), samples_with_mag, held, in_intervals);
  if (in_noise_measurement > 0) {
    s += fmt::format(", {} the noise was measured from", in_noise_measurement);
  }
  if (frozen) s += ": the value never changed -- a frozen magnetometer";
  if (decimated > 0) s += fmt::format(", {} left out to keep at most {}", decimated, points.size());
  s += ")";
  if (period_s > 0) s += fmt::format(" at {:.1f} Hz", 1.0 / period_s);
  if (!points.empty()) {
    s += fmt::format("; noise {:.3g} {:.3g} {:.3g} per sample ({})", sigma.x(), sigma.y(),
                     sigma.z(), noise_source);
  }
  if (bandwidth_hz > 0) {
    s += fmt::format(
        "; its {:g} Hz bandwidth attenuates the turning field by up to {:.3g} % (turning at up to "
        "{:.0f} deg/s)",
        bandwidth_hz, 100 * (1 - smallest_attenuation), fastest_turn_radps * 180 / M_PI);
  }
  return s;
}

bool MotionCollector::Push(const Sample& s, std::optional<double> t_device_s) {
  const std::int64_t sent_ns = clock_.Map(s.t_host_ns, s.t_device_s);
  if (!s.mag || !s.mag->allFinite()) return false;
  ++samples_with_mag_;
  if (previous_ && *previous_ == *s.mag) {
    ++held_;
    return false;
  }
  previous_ = *s.mag;
  if (++since_kept_ < stride_) {
    ++thinned_;
    return false;
  }
  since_kept_ = 0;
  MotionValue v;
  v.t_host_s = static_cast<double>(sent_ns) * 1e-9;
  v.t_device_s = t_device_s;
  v.mag = *s.mag;
  v.temp_c = s.temp_c;
  Keep(v);
  return true;
}

void MotionCollector::Add(const MotionValue& value) {
  previous_ = value.mag;
  Keep(value);
}

void MotionCollector::Keep(const MotionValue& value) {
  values_.push_back(value);
  if (values_.size() <= std::max<std::size_t>(max_values_, 2)) return;
  // Every other value dropped, and from now on only every stride-th new one taken.
  std::size_t w = 0;
  for (std::size_t i = 0; i < values_.size(); i += 2) values_[w++] = values_[i];
  thinned_ += static_cast<std::int64_t>(values_.size() - w);
  values_.resize(w);
  stride_ *= 2;
}

namespace {

// The attenuation of each of `kept` (pointers into `fresh`) by a first-order low-pass of
// `bandwidth_hz` (MotionOptions::mag_bandwidth_hz; all 1 when 0): the field's rate of turn at a
// value is the angle between its neighbours' directions about the values' centre over their time
// apart. Fills out's bandwidth_hz, fastest_turn_radps and smallest_attenuation.
std::vector<double> Attenuation(const std::vector<MotionValue>& fresh,
                                const std::vector<const MotionValue*>& kept, double bandwidth_hz,
                                MotionPoints* out) {
  std::vector<double> a(kept.size(), 1.0);
  if (!(bandwidth_hz > 0) || fresh.size() < 3) return a;
  std::vector<Eigen::Vector3d> values;
  for (const MotionValue* v : kept) values.push_back(v->mag);
  Eigen::Vector3d centre = Eigen::Vector3d::Zero();
  if (auto e = free::FitEllipsoid(values)) {
    centre = e->center;
  } else if (auto s = free::FitSphere(values)) {
    centre = s->center;
  } else {
    return a;  // no centre: the rate of turn is not known
  }
  const auto time_s = [](const MotionValue& v) {
    return v.t_device_s ? *v.t_device_s : v.t_host_s;
  };
  const double w_c = 2 * M_PI * bandwidth_hz;
  out->bandwidth_hz = bandwidth_hz;
  for (std::size_t j = 0; j < kept.size(); ++j) {
    const std::size_t i = static_cast<std::size_t>(kept[j] - fresh.data());
    const MotionValue& before = fresh[i > 0 ? i - 1 : i];
    const MotionValue& after = fresh[i + 1 < fresh.size() ? i + 1 : i];
    const double dt = time_s(after) - time_s(before);
    if (!(dt > 0)) continue;
    const Eigen::Vector3d u = (before.mag - centre).normalized();
    const Eigen::Vector3d v = (after.mag - centre).normalized();
    const double turn_radps = std::atan2(u.cross(v).norm(), u.dot(v)) / dt;
    a[j] = 1.0 / std::sqrt(1.0 + std::pow(turn_radps / w_c, 2));
    out->fastest_turn_radps = std::max(out->fastest_turn_radps, turn_radps);
    out->smallest_attenuation = std::min(out->smallest_attenuation, a[j]);
  }
  return a;
}

}  // namespace

MotionPoints MotionCollector::Select(const std::vector<FreeInterval>& intervals,
                                     const MotionOptions& options) const {
  MotionPoints out;
  out.samples_with_mag = samples_with_mag_;
  out.held = held_;
  const std::vector<MotionValue>& fresh = values_;
  out.frozen = fresh.size() == 1 && samples_with_mag_ > 1;
  if (fresh.size() < 2) return out;
  // The period between new values (the median spacing on the host's clock, or the device's).
  std::vector<double> gaps;
  for (std::size_t i = 1; i < fresh.size(); ++i) {
    const MotionValue& a = fresh[i - 1];
    const MotionValue& b = fresh[i];
    gaps.push_back(a.t_device_s && b.t_device_s ? *b.t_device_s - *a.t_device_s
                                                : b.t_host_s - a.t_host_s);
  }
  out.period_s = std::max(MedianOf(gaps), 1e-6);
  // The per-sample noise: pooled over the still intervals' own samples when they hold enough
  // (thousands of samples: sigma to a per cent; the noise meter's second has a hundred, and a
  // chi^2 over a thousand points would see its 7 %), else as given, else the points' scatter.
  double dof = 0;
  Eigen::Vector3d pooled = Eigen::Vector3d::Zero();
  int pooled_intervals = 0;
  for (const auto& iv : intervals) {
    if (iv.in_motion || !iv.mag || iv.mag->count < 2) continue;
    const double n = static_cast<double>(iv.mag->count - 1);
    pooled += n * iv.mag->covariance.diagonal();
    dof += n;
    ++pooled_intervals;
  }
  const bool use_pooled =
      dof >= options.min_pooled_samples && pooled.allFinite() && (pooled.array() > 0).all();
  // Outside the still intervals, with a margin of two periods on each side, and outside the
  // noise's measurement when that is what the points are weighed with.
  std::vector<std::pair<double, double>> still;
  for (const auto& iv : intervals) {
    if (!iv.in_motion) still.emplace_back(iv.t_start_s, iv.t_end_s);
  }
  std::sort(still.begin(), still.end());
  double measured_from_s = std::numeric_limits<double>::infinity(),
         measured_to_s = -measured_from_s;
  if (!use_pooled && options.mag_sigma && options.mag_sigma_measured_host_s) {
    std::tie(measured_from_s, measured_to_s) = *options.mag_sigma_measured_host_s;
  }
  std::vector<const MotionValue*> moving;
  std::size_t w = 0;
  const double margin = 2 * out.period_s;
  for (const MotionValue& v : fresh) {
    while (w < still.size() && still[w].second + margin < v.t_host_s) ++w;
    if (w < still.size() && v.t_host_s >= still[w].first - margin) {
      ++out.in_intervals;
      continue;
    }
    if (v.t_host_s >= measured_from_s && v.t_host_s <= measured_to_s) {
      ++out.in_noise_measurement;
      continue;
    }
    moving.push_back(&v);
  }
  // At most max_points, evenly spread over the new values in motion.
  const std::size_t max_points = static_cast<std::size_t>(std::max(options.max_points, 1));
  std::vector<const MotionValue*> kept;
  if (moving.size() <= max_points) {
    kept = moving;
  } else {
    for (std::size_t j = 0; j < max_points; ++j)
      kept.push_back(moving[j * moving.size() / max_points]);
  }
  out.decimated = static_cast<std::int64_t>(moving.size() - kept.size()) + thinned_;
  if (kept.empty()) return out;

  if (use_pooled) {
    out.sigma = (pooled / dof).cwiseSqrt();
    out.sigma_dof = dof;
    out.noise_source = fmt::format("pooled over the {} still intervals' {:.0f} samples",
                                   pooled_intervals, dof + pooled_intervals);
  } else if (options.mag_sigma) {
    out.sigma = *options.mag_sigma;
    out.sigma_dof = options.mag_sigma_dof;
    if (std::isfinite(out.sigma_dof) && options.mag_sigma_rate_hz > 0) {
      out.sigma_dof *= std::min(1.0, 1.0 / (out.period_s * options.mag_sigma_rate_hz));
    }
    out.noise_source = options.noise_source.empty() ? "given" : options.noise_source;
  } else {
    std::vector<Eigen::Vector3d> values;
    for (const MotionValue* v : kept) values.push_back(v->mag);
    out.sigma.setConstant(ScatterSigma(values));
    out.noise_source =
        "the points' scatter about an ellipsoid through them: the chi^2 is no check of the noise";
  }
  const std::vector<double> attenuation = Attenuation(fresh, kept, options.mag_bandwidth_hz, &out);
  const Eigen::Matrix3d covariance = out.sigma.cwiseAbs2().cwiseMax(1e-300).asDiagonal();
  for (std::size_t j = 0; j < kept.size(); ++j) {
    const MotionValue* v = kept[j];
    FreeInterval p;
    p.in_motion = true;
    p.t_start_s = v->t_host_s;
    p.t_end_s = p.t_start_s + out.period_s;
    if (v->t_device_s) {
      p.sensor_t_start_s = *v->t_device_s;
      p.sensor_t_end_s = *v->t_device_s + out.period_s;
    }
    TriadStats m;
    m.mean = v->mag;
    m.covariance = covariance;
    m.count = 1;
    p.mag = m;
    p.temp_c = v->temp_c;
    p.mag_attenuation = attenuation[j];
    out.points.push_back(std::move(p));
  }
  return out;
}

MotionPoints MagnetometerInMotion(const std::vector<Sample>& samples,
                                  const std::vector<FreeInterval>& intervals,
                                  const MotionOptions& options) {
  MotionCollector collector(std::numeric_limits<std::size_t>::max());
  for (const Sample& s : samples) collector.Push(s);
  return collector.Select(intervals, options);
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
    if (!mo.mag_sigma && out.found.noise) mo.TakeNoise(*out.found.noise);
    out.motion = MagnetometerInMotion(samples, out.found.intervals, mo);
    out.data.insert(out.data.end(), out.motion->points.begin(), out.motion->points.end());
  }
  return out;
}

}  // namespace turncal
