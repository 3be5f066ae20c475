#include "tools/noise_exports.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <vector>

namespace turncal::tools {
namespace {

constexpr const char* kTerms[] = {"Q", "N", "B", "K", "R"};

std::vector<const nlohmann::json*> AxesOf(const nlohmann::json& axes, const char* triad) {
  std::vector<const nlohmann::json*> out;
  for (const auto& a : axes)
    if (a.value("triad", "") == triad) out.push_back(&a);
  return out;
}

// The largest axis's IEEE term: its value (or, unresolved, its 95 % upper bound) and which.
struct Largest {
  double value = 0.0;
  std::string axis;
  bool upper_bound = false;
  bool found = false;
};
Largest LargestTerm(const std::vector<const nlohmann::json*>& axes, const char* term) {
  Largest best;
  for (const nlohmann::json* a : axes) {
    const nlohmann::json& ieee = a->value("ieee", nlohmann::json::object());
    if (!ieee.value("ok", false) || !ieee.contains(term)) continue;
    const nlohmann::json& t = ieee[term];
    const bool resolved = t.value("resolved", false);
    const double v = resolved ? t.value("value", 0.0) : t["ci95"][1].get<double>();
    if (!std::isfinite(v)) continue;
    if (!best.found || v > best.value) {
      best = {v, a->value("axis", ""), !resolved, true};
    }
  }
  return best;
}

double MaxOf(const std::vector<const nlohmann::json*>& axes, const char* key) {
  double v = 0.0;
  for (const nlohmann::json* a : axes) v = std::max(v, a->value(key, 0.0));
  return v;
}

// The Gauss-Markov term of the axis with the largest sigma among those whose correlation time
// the recording shows (1 s to ten longest cluster times): a shorter one is white noise by
// another name, a longer one an extrapolation.
void GaussMarkovOf(const std::vector<const nlohmann::json*>& axes, double* sigma, double* tau) {
  for (const nlohmann::json* a : axes) {
    const double s = a->value("gauss_markov_sigma", 0.0), t = a->value("gauss_markov_tau_s", 0.0);
    if (t >= 1.0 && t <= 10.0 * a->value("longest_tau_s", 0.0) && s > *sigma) *sigma = s, *tau = t;
  }
}

}  // namespace

std::string WarmUpText(const nlohmann::json& axes) {
  std::string o;
  for (const auto& a : axes) {
    const nlohmann::json& w = a.value("warm_up", nlohmann::json::object());
    o += fmt::format("{:<5} {:<4} ", a.value("triad", ""), a.value("axis", ""));
    if (!w.value("ok", false)) {
      o += fmt::format("no fit: {}\n", w.value("error", "?"));
    } else if (!w.value("resolved", false)) {
      o += fmt::format(
          "no transient from the first sample (amplitude {:.3g} +- {:.2g}): warm, "
          "or the recording started after switch-on\n",
          w.value("amplitude", 0.0), w.value("amplitude_sigma", 0.0));
    } else {
      o += fmt::format(
          "{:.0f} +- {:.0f} s to within {:.3g} (the Allan floor); amplitude {:.3g} +- {:.2g}, "
          "tau {:.0f} +- {:.0f} s\n",
          w.value("time_s", 0.0), w.value("time_sigma_s", 0.0), w.value("threshold", 0.0),
          w.value("amplitude", 0.0), w.value("amplitude_sigma", 0.0), w.value("tau_s", 0.0),
          w.value("tau_sigma_s", 0.0));
    }
  }
  return o;
}

std::string IeeeTermsText(const nlohmann::json& axes) {
  std::string o = fmt::format("{:<5} {:<4}", "triad", "axis");
  for (const char* t : kTerms) o += fmt::format(" {:>24}", t);
  o += "\n";
  std::string units_line;
  for (const auto& a : axes) {
    const std::string triad = a.value("triad", "");
    const nlohmann::json& ieee = a.value("ieee", nlohmann::json::object());
    o += fmt::format("{:<5} {:<4}", triad, a.value("axis", ""));
    if (!ieee.value("ok", false)) {
      o += fmt::format(" no fit: {}\n", ieee.value("error", "?"));
      continue;
    }
    for (const char* t : kTerms) {
      const nlohmann::json& d = ieee[t]["datasheet"];
      const std::string cell =
          ieee[t].value("resolved", false)
              ? fmt::format("{:.3g} +- {:.2g}", d.value("value", 0.0), d.value("sigma", 0.0))
              : fmt::format("< {:.3g}", d["ci95"][1].get<double>());
      o += fmt::format(" {:>24}", cell);
    }
    o += "\n";
  }
  // The units of each triad present, once.
  for (const char* triad : {"acc", "gyr", "mag"}) {
    const auto of = AxesOf(axes, triad);
    if (of.empty()) continue;
    const nlohmann::json& ieee = of.front()->value("ieee", nlohmann::json::object());
    if (!ieee.value("ok", false)) continue;
    o += fmt::format("  {} units:", triad);
    for (const char* t : kTerms) {
      o += fmt::format(" {} {}{}", t, ieee[t]["datasheet"].value("unit", ""),
                       t[0] == 'R' ? "" : ",");
    }
    o += "\n";
  }
  return o;
}

std::string KalibrImuYaml(const nlohmann::json& axes, const std::string& source,
                          const std::string& rostopic, std::string* error) {
  const auto acc = AxesOf(axes, "acc"), gyr = AxesOf(axes, "gyr");
  if (acc.empty() && gyr.empty()) {
    *error = "Kalibr's imu.yaml needs an accelerometer or a gyroscope axis";
    return "";
  }
  double rate = 0.0;
  for (const auto& a : axes) rate = std::max(rate, a.value("rate_hz", 0.0));
  std::string o = fmt::format(
      "# Kalibr IMU noise parameters from `turncal noise {}` (IEEE Std 952-2020 terms fitted to\n"
      "# the overlapping Allan variance with their sigma; docs/NOISE.md). Kalibr's noise_density\n"
      "# is IEEE's N (the Allan deviation's -1/2 line at tau = 1 s), its random_walk IEEE's K\n"
      "# (the +1/2 line at tau = 3 s), both continuous-time: Kalibr divides them by sqrt(dt)\n"
      "# itself. Each is the largest of the three axes. A term the recording could not tell\n"
      "# from zero is its 95 % upper bound (said so beside it). Kalibr's own advice is to\n"
      "# inflate these for the vibration and temperature of a real run; they are the sensor's\n"
      "# at rest.\n",
      source);
  auto line = [&](const char* key, const std::vector<const nlohmann::json*>& of, const char* term,
                  const char* unit) {
    const Largest l = LargestTerm(of, term);
    if (!l.found) {
      o += fmt::format("# {}: not measured (no fit)\n", key);
      return;
    }
    o += fmt::format("{}: {:.6g}  # [{}] IEEE {} of axis {}{}\n", key, l.value, unit, term, l.axis,
                     l.upper_bound ? ", its 95 % upper bound (not resolved)" : "");
  };
  if (!acc.empty()) {
    line("accelerometer_noise_density", acc, "N", "m/s^2/sqrt(Hz)");
    line("accelerometer_random_walk", acc, "K", "m/s^3/sqrt(Hz)");
  }
  if (!gyr.empty()) {
    line("gyroscope_noise_density", gyr, "N", "rad/s/sqrt(Hz)");
    line("gyroscope_random_walk", gyr, "K", "rad/s^2/sqrt(Hz)");
  }
  o += fmt::format("rostopic: {}  # the IMU's ROS topic\n", rostopic);
  o += fmt::format("update_rate: {:.6g}  # [Hz] the recording's sample rate\n", rate);
  return o;
}

std::string StationNoiseToml(const nlohmann::json& axes, const std::string& source,
                             std::string* error) {
  const auto acc = AxesOf(axes, "acc"), mag = AxesOf(axes, "mag");
  if (acc.empty() && mag.empty()) {
    *error = "the [station] noise prior needs an accelerometer or a magnetometer axis";
    return "";
  }
  std::string o = fmt::format(
      "# turncald's noise prior measured on this sensor at rest (`turncal noise {}`): the model\n"
      "# turncald's calibrator uses, white noise, a Gauss-Markov bias instability and a bias\n"
      "# random walk, each the largest of the three axes (docs/ACCURACY.md \"Drift\"). Paste into\n"
      "# turncald.toml; the session's own poses identify the drift's strength on top of it.\n"
      "[station]\n",
      source);
  if (!acc.empty()) {
    const double density = MaxOf(acc, "white_density");
    if (density > 0) {
      o += fmt::format(
          "acc_noise_density = {:.6g}  # m/s^2/sqrt(Hz), one-sided (sqrt(2) x IEEE N)\n", density);
    } else {
      o += "# acc_noise_density: no white term fitted (the class's stays)\n";
    }
    double sigma = 0.0, tau = 0.0;
    GaussMarkovOf(acc, &sigma, &tau);
    if (sigma > 0) {
      o += fmt::format("acc_bias_instability = {:.6g}  # m/s^2, Gauss-Markov sigma\n", sigma);
      o += fmt::format("bias_tau_s = {:.6g}  # s, its correlation time\n", tau);
    } else {
      o += "# acc_bias_instability: no Gauss-Markov term with a correlation time this recording "
           "shows (the class's stays)\n";
    }
    o += fmt::format("acc_random_walk = {:.6g}  # m/s^2/sqrt(s) (IEEE K)\n",
                     MaxOf(acc, "random_walk"));
  }
  if (!mag.empty()) {
    double rms = 0.0;
    for (const nlohmann::json* a : mag) {
      rms = std::max(rms, a->value("white_density", 0.0) * std::sqrt(a->value("rate_hz", 0.0) / 2));
    }
    if (rms > 0) o += fmt::format("mag_noise_rms = {:.6g}  # G per sample\n", rms);
    double sigma = 0.0, tau = 0.0;
    GaussMarkovOf(mag, &sigma, &tau);
    if (sigma > 0) {
      o += fmt::format("mag_bias_instability = {:.6g}  # G, Gauss-Markov sigma\n", sigma);
    }
    o += fmt::format("mag_random_walk = {:.6g}  # G/sqrt(s)\n", MaxOf(mag, "random_walk"));
  }
  return o;
}

}  // namespace turncal::tools
