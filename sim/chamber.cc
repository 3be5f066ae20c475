#include "sim/chamber.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <sstream>

namespace turncal {

double ChamberProfile::AirAt(double t_s) const {
  if (t_s <= 0) return start_c;
  double from_c = start_c, t0_s = 0.0;
  for (const ChamberStep& s : steps) {
    const double move_s =
        s.rate_c_per_min > 0 ? std::abs(s.setpoint_c - from_c) / s.rate_c_per_min * 60.0 : 0.0;
    if (t_s < t0_s + move_s) return from_c + (s.setpoint_c - from_c) * (t_s - t0_s) / move_s;
    if (t_s < t0_s + move_s + s.hold_s || &s == &steps.back()) return s.setpoint_c;
    t0_s += move_s + s.hold_s;
    from_c = s.setpoint_c;
  }
  return from_c;
}

double ChamberProfile::duration_s() const {
  double from_c = start_c, t_s = 0.0;
  for (const ChamberStep& s : steps) {
    if (s.rate_c_per_min > 0) t_s += std::abs(s.setpoint_c - from_c) / s.rate_c_per_min * 60.0;
    t_s += s.hold_s;
    from_c = s.setpoint_c;
  }
  return t_s;
}

double ChamberProfile::middle_c() const {
  double lo = start_c, hi = start_c;
  for (const ChamberStep& s : steps)
    lo = std::min(lo, s.setpoint_c), hi = std::max(hi, s.setpoint_c);
  return 0.5 * (lo + hi);
}

bool ChamberProfile::IsValid(std::string* error) const {
  auto fail = [&](const std::string& m) {
    if (error) *error = m;
    return false;
  };
  auto in_range = [](double t) { return std::isfinite(t) && t >= -70.0 && t <= 180.0; };
  if (!in_range(start_c)) return fail("the chamber's start must be within -70 .. 180 degC");
  for (std::size_t i = 0; i < steps.size(); ++i) {
    const ChamberStep& s = steps[i];
    if (!in_range(s.setpoint_c)) {
      return fail(
          fmt::format("chamber step {}: the set-point must be within -70 .. 180 degC", i + 1));
    }
    if (!(s.rate_c_per_min >= 0) || !std::isfinite(s.rate_c_per_min)) {
      return fail(fmt::format("chamber step {}: the rate must be finite and >= 0", i + 1));
    }
    if (!(s.hold_s >= 0) || !std::isfinite(s.hold_s)) {
      return fail(fmt::format("chamber step {}: the hold must be finite and >= 0 s", i + 1));
    }
  }
  return true;
}

bool ChamberProfile::Parse(const std::string& text, ChamberProfile* out, std::string* error) {
  auto fail = [&](const std::string& m) {
    if (error) *error = "chamber profile: " + m;
    return false;
  };
  ChamberProfile p;
  std::stringstream all(text);
  std::string part;
  bool first = true;
  int index = 0;
  while (std::getline(all, part, ';')) {
    std::istringstream in(part);
    if (first) {
      if (!(in >> p.start_c)) return fail("it starts with the start temperature, e.g. '25; ...'");
      first = false;
      continue;
    }
    ++index;
    std::string kind;
    ChamberStep s;
    if (!(in >> kind)) continue;  // an empty step ("25;")
    if (kind == "soak") {
      if (!(in >> s.setpoint_c >> s.hold_s)) {
        return fail(fmt::format("step {}: 'soak T HOLD_S'", index));
      }
    } else if (kind == "ramp") {
      if (!(in >> s.setpoint_c >> s.rate_c_per_min)) {
        return fail(fmt::format("step {}: 'ramp T RATE_C_PER_MIN [HOLD_S]'", index));
      }
      if (!(in >> s.hold_s)) s.hold_s = 0.0;
      if (!(s.rate_c_per_min > 0))
        return fail(fmt::format("step {}: a ramp's rate must be > 0", index));
    } else {
      return fail(fmt::format("step {}: '{}' is neither 'soak' nor 'ramp'", index, kind));
    }
    std::string rest;
    if (in >> rest) return fail(fmt::format("step {}: unexpected '{}'", index, rest));
    p.steps.push_back(s);
  }
  if (first) return fail("empty");
  std::string why;
  if (!p.IsValid(&why)) return fail(why);
  *out = p;
  return true;
}

std::string ChamberProfile::ToString() const {
  std::string out = fmt::format("{:g}", start_c);
  for (const ChamberStep& s : steps) {
    if (s.rate_c_per_min > 0) {
      out += fmt::format("; ramp {:g} {:g} {:g}", s.setpoint_c, s.rate_c_per_min, s.hold_s);
    } else {
      out += fmt::format("; soak {:g} {:g}", s.setpoint_c, s.hold_s);
    }
  }
  return out;
}

ChamberProfile ChamberProfile::Soaks(double start_c, const std::vector<double>& plateaus_c,
                                     double rate_c_per_min, double hold_s) {
  ChamberProfile p;
  p.start_c = start_c;
  for (double t : plateaus_c) p.steps.push_back({t, rate_c_per_min, hold_s});
  return p;
}

bool DieThermal::IsValid(std::string* error) const {
  auto fail = [&](const std::string& m) {
    if (error) *error = m;
    return false;
  };
  if (!(tau_s > 0) || !std::isfinite(tau_s)) return fail("the die's time constant must be > 0 s");
  if (!std::isfinite(self_heating_c)) return fail("the self-heating must be finite");
  if (!(self_heating_tau_s > 0) || !std::isfinite(self_heating_tau_s)) {
    return fail("the self-heating's time constant must be > 0 s");
  }
  if (!(quantum_c >= 0) || !std::isfinite(quantum_c)) {
    return fail("the temperature's quantum must be finite and >= 0");
  }
  if (!(hysteresis_c >= 0) || !std::isfinite(hysteresis_c)) {
    return fail("the hysteresis must be finite and >= 0 degC");
  }
  return true;
}

DieTemperature::DieTemperature(const ChamberProfile& chamber, const DieThermal& die)
    : chamber_(chamber), die_(die), die_c_(chamber.AirAt(0.0)), parameter_c_(die_c_) {}

double DieTemperature::Advance(double t_s) {
  const double dt = t_s - t_s_;
  if (dt > 0) {
    // The die relaxes toward the air plus the self-heating at the step's midpoint.
    const double mid = t_s_ + 0.5 * dt;
    const double target = chamber_.AirAt(mid) +
                          die_.self_heating_c * (1.0 - std::exp(-mid / die_.self_heating_tau_s));
    die_c_ += (target - die_c_) * (1.0 - std::exp(-dt / die_.tau_s));
    t_s_ = t_s;
    const double half = 0.5 * die_.hysteresis_c;
    parameter_c_ = std::clamp(parameter_c_, die_c_ - half, die_c_ + half);
  }
  return die_c_;
}

double DieTemperature::Reported(double die_c) const {
  if (die_.quantum_c <= 0) return die_c;
  return std::round(die_c / die_.quantum_c) * die_.quantum_c;
}

}  // namespace turncal
