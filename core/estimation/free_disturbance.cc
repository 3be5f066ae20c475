#include "core/estimation/free_disturbance.h"

#include "core/estimation/free_calibrator.h"
#include "core/estimation/free_motion.h"

#include <fmt/format.h>

#include <algorithm>
#include <boost/math/special_functions/erf.hpp>
#include <cmath>

namespace turncal {

MotionDepartures FindDisturbedMotion(const FreeModel& model, const FreeData& data,
                                     const Eigen::VectorXd& theta, double sigmas) {
  MotionDepartures out;
  std::vector<int> index;
  std::vector<double> departure;
  for (const auto& m : model.Misfits(data, theta)) {
    if (m.kind != "norm" || m.interval < 0 ||
        m.interval >= static_cast<int>(data.intervals.size()) ||
        !data.intervals[static_cast<std::size_t>(m.interval)].in_motion ||
        !std::isfinite(m.value)) {
      continue;
    }
    index.push_back(m.interval);
    departure.push_back(m.value);
  }
  const std::size_t n = departure.size();
  if (n < 20) return out;
  const double centre = MedianOf(departure);
  std::vector<double> absolute(n), step(n - 1);
  for (std::size_t i = 0; i < n; ++i) absolute[i] = std::abs(departure[i] - centre);
  for (std::size_t i = 0; i + 1 < n; ++i) step[i] = std::abs(departure[i + 1] - departure[i]);
  out.scatter = 1.4826 * MedianOf(absolute);
  out.step_noise = 1.4826 * MedianOf(step) / std::sqrt(2.0);
  if (!(out.scatter > 0)) return out;
  // P(|z| > k) = erfc(k / sqrt 2) = 1e-3 / n.
  const double bound = std::sqrt(2.0) * boost::math::erfc_inv(1e-3 / static_cast<double>(n));
  const double limit = std::max(sigmas, bound);
  const double field =
      data.context.field_magnitude > 0 ? data.context.field_magnitude : 1.0;  // relative: 1
  for (std::size_t i = 0; i < n; ++i) {
    const double z = absolute[i] / out.scatter;
    if (z <= limit) continue;
    out.disturbed.push_back(index[i]);
    if (z > out.largest_sigmas) {
      out.largest_sigmas = z;
      out.largest_percent = 100.0 * std::abs(departure[i]) / field;
    }
  }
  return out;
}

std::vector<int> DisturbedSpan(const FreeData& data, const std::vector<int>& disturbed) {
  if (disturbed.empty()) return {};
  const auto at_s = [&data](std::size_t i) {
    return 0.5 * (data.intervals[i].t_start_s + data.intervals[i].t_end_s);
  };
  // One value's spacing: the median step between samples in motion.
  std::vector<std::size_t> motion;
  for (std::size_t i = 0; i < data.intervals.size(); ++i) {
    if (data.intervals[i].in_motion) motion.push_back(i);
  }
  std::vector<double> steps;
  for (std::size_t k = 1; k < motion.size(); ++k) {
    steps.push_back(std::abs(at_s(motion[k]) - at_s(motion[k - 1])));
  }
  const double spacing_s = steps.empty() ? 0.0 : MedianOf(steps);
  // The runs, each widened; overlapping windows merge.
  std::vector<double> times;
  for (int i : disturbed) times.push_back(at_s(static_cast<std::size_t>(i)));
  std::sort(times.begin(), times.end());
  std::vector<std::pair<double, double>> windows;
  std::size_t first = 0;
  for (std::size_t k = 1; k <= times.size(); ++k) {
    if (k < times.size() && times[k] - times[k - 1] < kDisturbanceJoinS) continue;
    const double t0 = times[first], t1 = times[k - 1];
    const double margin = 0.5 * (t1 - t0) + spacing_s;
    if (!windows.empty() && t0 - margin <= windows.back().second) {
      windows.back().second = t1 + margin;
    } else {
      windows.emplace_back(t0 - margin, t1 + margin);
    }
    first = k;
  }
  std::vector<int> out;
  std::size_t w = 0;
  for (std::size_t i : motion) {
    const double t = at_s(i);
    while (w < windows.size() && t > windows[w].second) ++w;
    if (w == windows.size()) break;
    if (t >= windows[w].first) out.push_back(static_cast<int>(i));
  }
  return out;
}

FreeEstimate LeaveOutDisturbedMotion(
    const FreeModel& model, const FreeData& data, const FreeCalibratorOptions& options,
    const std::function<FreeEstimate(const FreeData&, bool whiten)>& fit) {
  // The fit of the values kept whitened together, when their noise was measured correlated.
  const auto whitened = [&](FreeEstimate white, const FreeData& kept) {
    if (!options.whiten_correlated_motion || !white.estimate.ok ||
        !white.correlation.correlated()) {
      return white;
    }
    FreeEstimate again = fit(kept, true);
    if (again.estimate.ok) return again;
    // The independent fit's sigmas are too small for correlated noise: kept, but not passed.
    const std::string why = fmt::format(
        "the values in motion's noise correlates ({:.2f} over {} pairs) but the fit that accounts "
        "for it failed ({}): the sigmas of the fit that treats them as independent are too small",
        white.correlation.lag_one, white.correlation.pairs, again.estimate.error);
    white.estimate.warnings.push_back(why);
    white.gate_passed = false;
    white.gate_reasons.push_back(why);
    return white;
  };
  FreeEstimate out = fit(data, false);
  if (!(options.disturbance_sigmas > 0) || out.motion_points == 0 || !out.estimate.ok) {
    return whitened(std::move(out), data);
  }
  const int motion_points = out.motion_points;
  // The samples in motion disturbed at the latest fit, always judged over all of them (a value
  // left out may come back); the fit without them; until the set stops changing (four rounds).
  std::vector<int> left_out;
  FreeData kept;  // without left_out (empty: data)
  int detected = 0;
  MotionDepartures at =
      FindDisturbedMotion(model, data, out.estimate.theta, options.disturbance_sigmas);
  std::vector<int> span = DisturbedSpan(data, at.disturbed);
  for (int round = 0; round < 4 && span != left_out; ++round) {
    std::vector<bool> drop(data.intervals.size(), false);
    for (int i : span) drop[static_cast<std::size_t>(i)] = true;
    FreeData rest;
    rest.context = data.context;
    rest.upstream_theta = data.upstream_theta;
    rest.upstream_covariance = data.upstream_covariance;
    for (std::size_t i = 0; i < data.intervals.size(); ++i) {
      if (!drop[i]) rest.intervals.push_back(data.intervals[i]);
    }
    FreeEstimate again = fit(rest, false);
    if (!again.estimate.ok) break;  // keep the last fit that worked, with what it left out
    out = std::move(again);
    kept = std::move(rest);
    left_out = std::move(span);
    detected = static_cast<int>(at.disturbed.size());
    at = FindDisturbedMotion(model, data, out.estimate.theta, options.disturbance_sigmas);
    span = DisturbedSpan(data, at.disturbed);
  }
  // A disturbance as long as a good part of the capture pulls the fit and widens the scatter it
  // is judged by until nothing stands out; but the departures then wander far more than they
  // change from one value to the next, which white noise and the bias's slow drift cannot do.
  const double wander = at.step_noise > 0 ? at.scatter / at.step_noise : 0.0;
  out = whitened(std::move(out), left_out.empty() ? data : kept);
  out.field_wander = wander;
  if (wander > options.max_field_wander) {
    out.gate_reasons.push_back(fmt::format(
        "the field's magnitude wanders: its departures from the fit scatter {:.1f} times as much "
        "as they change from one value to the next (at most {:.0f}): a magnet, steel or a motor "
        "near for a long part of the capture, or a magnetometer the model does not fit",
        wander, options.max_field_wander));
    out.gate_passed = false;
  }
  if (left_out.empty()) return out;
  FieldDisturbance d;
  d.values = static_cast<int>(left_out.size());
  d.detected = detected;
  d.of = motion_points;
  const double origin_s = data.intervals.front().t_start_s;
  d.t0_s = data.intervals[static_cast<std::size_t>(left_out.front())].t_start_s - origin_s;
  d.t1_s = data.intervals[static_cast<std::size_t>(left_out.back())].t_end_s - origin_s;
  // The largest departure among those left out, at the final fit, against its scatter.
  const MotionDepartures all = FindDisturbedMotion(model, data, out.estimate.theta, 0.0);
  d.largest_percent = all.largest_percent;
  d.largest_sigmas = all.largest_sigmas;
  out.estimate.warnings.push_back(DisturbanceText(d));
  if (d.share() > options.max_disturbed_share) {
    out.gate_reasons.push_back(fmt::format(
        "the field was disturbed in {:.0f} % of the values in motion (more than {:.0f} %): "
        "calibrate away from magnets, steel and motors",
        100 * d.share(), 100 * options.max_disturbed_share));
    out.gate_passed = false;
  }
  out.disturbance = d;
  return out;
}

std::string DisturbanceText(const FieldDisturbance& d) {
  return fmt::format(
      "the field's magnitude departed from the fit by up to {:.3g} % ({:.0f} robust sigmas) in "
      "{} of {} values in motion: a magnet or steel nearby? Left out of the fit with the time "
      "about them, {} values between {:.2f} and {:.2f} s",
      d.largest_percent, d.largest_sigmas, d.detected, d.of, d.values, d.t0_s, d.t1_s);
}

}  // namespace turncal
