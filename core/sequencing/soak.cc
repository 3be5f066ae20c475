#include "core/sequencing/soak.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>

namespace turncal {

bool SoakOptions::IsValid(std::string* error) const {
  auto fail = [&](const char* m) {
    if (error) *error = m;
    return false;
  };
  if (!std::isfinite(setpoint_c)) return fail("the chamber's set-point must be a number (degC)");
  if (!(max_rate_c_per_min > 0) || !std::isfinite(max_rate_c_per_min)) {
    return fail("[thermal] soak_rate_c_per_min must be > 0");
  }
  if (!(window_s >= 1) || !std::isfinite(window_s))
    return fail("[thermal] soak_window_s must be >= 1");
  if (!(timeout_s > 0)) return fail("[thermal] soak_timeout_s must be > 0");
  return true;
}

void SoakTracker::Add(double t_s, double temp_c, double window_s) {
  if (!std::isfinite(t_s) || !std::isfinite(temp_c)) return;
  if (!points_.empty() && t_s < points_.back().t_s + 0.1) return;
  points_.push_back({t_s, temp_c});
  while (!points_.empty() && points_.front().t_s < t_s - window_s) points_.pop_front();
}

std::optional<double> SoakTracker::RateCPerMin(double window_s) const {
  if (points_.size() < 3 || points_.back().t_s - points_.front().t_s < 0.8 * window_s) {
    return std::nullopt;
  }
  // Least squares about the means (the times' digits kept).
  double mt = 0, mT = 0;
  for (const Point& p : points_) mt += p.t_s, mT += p.temp_c;
  mt /= static_cast<double>(points_.size());
  mT /= static_cast<double>(points_.size());
  double stt = 0, stT = 0;
  for (const Point& p : points_) {
    stt += (p.t_s - mt) * (p.t_s - mt);
    stT += (p.t_s - mt) * (p.temp_c - mT);
  }
  return stt > 0 ? std::optional<double>(60.0 * stT / stt) : std::nullopt;
}

std::optional<double> SoakTracker::latest_c() const {
  return points_.empty() ? std::nullopt : std::optional<double>(points_.back().temp_c);
}

bool SoakTracker::Settled(const SoakOptions& soak, std::string* why) const {
  const std::optional<double> rate = RateCPerMin(soak.window_s);
  const std::optional<double> now = latest_c();
  // A channel that reads exactly the same for the whole window while the set-point is degrees
  // away has most likely stuck: a settled die still shows its noise or its last digit moving.
  bool stuck = false;
  if (rate && now && std::abs(*now - soak.setpoint_c) > 2.0) {
    stuck = std::all_of(points_.begin(), points_.end(),
                        [&](const Point& p) { return p.temp_c == points_.front().temp_c; });
  }
  if (rate && !stuck && std::abs(*rate) < soak.max_rate_c_per_min) return true;
  if (why && stuck) {
    *why = fmt::format(
        "waiting for the soak at {:.1f} degC: the sensor's temperature reads exactly {:.2f} degC "
        "for {:.0f} s, {:.1f} degC from the set-point (a stuck temperature channel?)",
        soak.setpoint_c, *now, soak.window_s, std::abs(*now - soak.setpoint_c));
    return false;
  }
  if (why) {
    if (!now) {
      *why =
          fmt::format("waiting for the soak at {:.1f} degC: the device reports no temperature yet",
                      soak.setpoint_c);
    } else if (!rate) {
      *why = fmt::format(
          "waiting for the soak at {:.1f} degC: the sensor's temperature {:.2f} degC is watched "
          "for {:.0f} s before it can be called settled",
          soak.setpoint_c, *now, soak.window_s);
    } else {
      *why = fmt::format(
          "waiting for the soak at {:.1f} degC: the sensor's temperature {:.2f} degC moves {:+.2f} "
          "degC/min (settled below {:.2f} over {:.0f} s), {:.1f} degC from the set-point",
          soak.setpoint_c, *now, *rate, soak.max_rate_c_per_min, soak.window_s,
          std::abs(*now - soak.setpoint_c));
    }
  }
  return false;
}

}  // namespace turncal
