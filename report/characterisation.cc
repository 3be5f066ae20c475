#include "report/characterisation.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <optional>

#include "core/analysis/allan_edf.h"
#include "core/modeling/free_model.h"
#include "core/modeling/measurement_model.h"
#include "protocol/calibration_json.h"
#include "protocol/free_json.h"
#include "report/analysis.h"

namespace turncal::report {
namespace {

constexpr double kG = 9.80665;
constexpr double kRadToDeg = 180.0 / M_PI;
constexpr double kRadPerSToDegPerH = kRadToDeg * 3600.0;

const char* const kAxes[3] = {"x", "y", "z"};

// A path's last component: the report names files, the sources list has the full paths.
std::string Base(const std::string& path) {
  const std::size_t slash = path.find_last_of('/');
  return slash == std::string::npos ? path : path.substr(slash + 1);
}

// The recording an axis came from (the tool sets "source"), else the rest's sources together.
std::string AxisSource(const nlohmann::json& axis, const std::string& fallback) {
  return axis.contains("source") ? Base(axis["source"].get<std::string>()) : fallback;
}

// The triad a model calibrates, as the model says (a turntable model's or a free one's; a
// thermal model by its stem, "accel13@T" as accel13).
std::string TriadOfModel(const std::string& model) {
  const std::string stem = model.substr(0, model.find('@'));
  std::string error;
  std::optional<SensorKind> kind;
  if (auto m = MakeModel(stem, ModelContext{}, &error)) {
    kind = m->sensor();
  } else if (auto f = MakeFreeModel(stem, FreeContext{}, &error)) {
    kind = f->sensor();
  }
  if (!kind) return "";
  switch (*kind) {
    case SensorKind::kAccelerometer:
      return "accelerometer";
    case SensorKind::kGyroscope:
      return "gyroscope";
    case SensorKind::kMagnetometer:
      return "magnetometer";
  }
  return "";
}

// A free calibration: turncald's document says so, `turncal free --json`'s entries by their
// model.
bool IsFree(const nlohmann::json& doc) {
  const auto names = FreeModelNames();
  return protocol::IsFreeCalibration(doc) ||
         std::find(names.begin(), names.end(), doc.value("model", "")) != names.end();
}

struct Estimate {
  const nlohmann::json* doc = nullptr;
  std::string source, model, time;
  bool free = false;
  std::optional<std::pair<double, double>> Param(const std::string& name) const {
    const nlohmann::json& p = doc->value("params", nlohmann::json::object());
    if (!p.contains(name) || !p[name].is_object()) return std::nullopt;
    const nlohmann::json& v = p[name];
    if (!v.contains("value") || !v["value"].is_number()) return std::nullopt;
    const double sigma =
        v.contains("sigma") && v["sigma"].is_number() ? v["sigma"].get<double>() : NAN;
    return std::make_pair(v["value"].get<double>(), sigma);
  }
  std::string From() const {
    return fmt::format("{} ({}{}{})", model, free ? "free, " : "turntable, ", Base(source),
                       time.empty() ? "" : ", " + time);
  }
};

CharacteristicRow Row(const std::string& triad, const std::string& item,
                      const std::string& standard, const std::string& axis) {
  CharacteristicRow r;
  r.triad = triad;
  r.item = item;
  r.standard = standard;
  r.axis = axis;
  return r;
}

class Builder {
 public:
  explicit Builder(Characterisation* out) : out_(out) {}

  void Measured(const std::string& triad, const std::string& item, const std::string& standard,
                const std::string& axis, double value, double sigma, const std::string& unit,
                const std::string& from) {
    CharacteristicRow r = Row(triad, item, standard, axis);
    r.measured = true;
    r.value = value;
    r.u95 = std::isfinite(sigma) ? 2.0 * sigma : NAN;
    r.unit = unit;
    r.from = from;
    out_->rows.push_back(r);
  }
  void Interval(const std::string& triad, const std::string& item, const std::string& standard,
                const std::string& axis, double value, double low, double high, bool upper_bound,
                const std::string& unit, const std::string& from) {
    CharacteristicRow r = Row(triad, item, standard, axis);
    r.measured = true;
    r.value = value;
    r.has_interval = true;
    r.low95 = low;
    r.high95 = high;
    r.upper_bound = upper_bound;
    r.unit = unit;
    r.from = from;
    out_->rows.push_back(r);
  }
  void Missing(const std::string& triad, const std::string& item, const std::string& standard,
               const std::string& why) {
    CharacteristicRow r = Row(triad, item, standard, "");
    r.from = why;
    out_->rows.push_back(r);
  }

 private:
  Characterisation* out_;
};

// The axis triplets of a model's parameters: name per axis, the conversion of a value to the
// display unit, and an offset subtracted first (a gain's 1, alpha3's pi/2).
struct Triplet {
  Triplet() = default;
  Triplet(std::vector<std::string> n, std::vector<std::string> a, double o = 0.0)
      : names(std::move(n)), axes(std::move(a)), offset(o) {}
  std::vector<std::string> names;
  std::vector<std::string> axes;
  double offset = 0.0;
};

void AddTriplet(Builder* b, const Estimate& e, const std::string& triad, const std::string& item,
                const std::string& standard, const Triplet& t, double factor,
                const std::string& unit) {
  for (std::size_t i = 0; i < t.names.size(); ++i) {
    const auto p = e.Param(t.names[i]);
    if (!p) continue;
    b->Measured(triad, item, standard, t.axes[i], (p->first - t.offset) * factor,
                p->second * factor, unit, e.From() + " " + t.names[i]);
  }
}

// A turntable model's scale factors, non-orthogonality (alpha3 as its deviation from 90 deg) and
// misalignment to the case: the same parameters in every accelerometer and gyroscope model.
void AddTurntableGeometry(Builder* b, const Estimate& e, const std::string& triad,
                          const std::string& scale_item, const std::string& standard) {
  AddTriplet(b, e, triad, scale_item, standard, {{"Sx", "Sy", "Sz"}, {"x", "y", "z"}}, 1e6, "ppm");
  AddTriplet(b, e, triad, "non-orthogonality", standard,
             {{"alpha1", "alpha2"}, {"alpha1", "alpha2"}}, 1e3, "mrad");
  AddTriplet(b, e, triad, "non-orthogonality", standard,
             {{"alpha3"}, {"alpha3 - 90 deg"}, M_PI / 2}, 1e3, "mrad");
  AddTriplet(b, e, triad, "misalignment to the case", standard,
             {{"eps_x", "eps_y", "eps_z"}, {"x", "y", "z"}}, 1e3, "mrad");
}

// The turn-on repeatability of each bias axis over the sessions' estimates: the scatter of the
// biases beyond their own sigma, with the chi^2 interval of the scatter (k - 1 degrees of
// freedom).
void AddRepeatability(Builder* b, const std::vector<Estimate>& sessions, const std::string& triad,
                      const std::string& standard, double factor, const std::string& unit) {
  const int k = static_cast<int>(sessions.size());
  for (int axis = 0; axis < 3; ++axis) {
    const std::string name = std::string("b") + kAxes[axis];
    std::vector<double> v, s2;
    for (const Estimate& e : sessions) {
      const auto p = e.Param(name);
      if (!p) continue;
      v.push_back(p->first);
      s2.push_back(std::isfinite(p->second) ? p->second * p->second : 0.0);
    }
    if (v.size() < 2) continue;
    const double n = static_cast<double>(v.size());
    double mean = 0, within = 0;
    for (std::size_t i = 0; i < v.size(); ++i) mean += v[i] / n, within += s2[i] / n;
    double scatter = 0;
    for (double x : v) scatter += (x - mean) * (x - mean) / (n - 1);
    const VarianceInterval ci = ChiSquaredInterval(scatter, n - 1, 0.95);
    const double value = std::sqrt(std::max(0.0, scatter - within));
    const double low = std::sqrt(std::max(0.0, ci.low - within));
    const double high = std::sqrt(std::max(0.0, ci.high - within));
    b->Interval(triad, "bias turn-on repeatability (1 sigma)", standard, kAxes[axis],
                value * factor, low * factor, high * factor, false, unit,
                fmt::format("{} sessions' {} (scatter {:.3g} {} beyond each estimate's sigma; the "
                            "interval from chi^2 with {} dof)",
                            k, name, std::sqrt(scatter) * factor, unit, v.size() - 1));
  }
}

// IEEE 952's terms of one triad's axes (RestNoiseAxesJson "ieee"), in the datasheet's units.
void AddNoise(Builder* b, const nlohmann::json& axes, const std::string& triad,
              const std::string& key, const std::string& standard, const std::string& source) {
  static const std::map<std::string, std::string> kNames = {
      {"Q", "quantisation Q"},
      {"N", "random walk N (angle / velocity)"},
      {"B", "bias instability B"},
      {"K", "rate random walk K"},
      {"R", "rate ramp R"}};
  bool any = false;
  for (const char* term : {"Q", "N", "B", "K", "R"}) {
    for (const auto& a : axes) {
      if (a.value("triad", "") != key) continue;
      const nlohmann::json& ieee = a.value("ieee", nlohmann::json::object());
      if (!ieee.value("ok", false) || !ieee.contains(term)) continue;
      const nlohmann::json& t = ieee[term];
      const nlohmann::json& d = t["datasheet"];
      const bool resolved = t.value("resolved", false);
      const double hi = d["ci95"][1].get<double>();
      any = true;
      if (resolved) {
        b->Interval(
            triad, kNames.at(term), standard, a.value("axis", ""), d.value("value", 0.0),
            d["ci95"][0].get<double>(), hi, false, d.value("unit", ""),
            fmt::format("{} (1 sigma {:.3g})", AxisSource(a, source), d.value("sigma", 0.0)));
      } else {
        b->Interval(triad, kNames.at(term), standard, a.value("axis", ""), hi, 0.0, hi, true,
                    d.value("unit", ""),
                    AxisSource(a, source) + " (not resolved: the 95 % upper bound)");
      }
    }
  }
  if (!any) {
    b->Missing(triad, "noise terms Q, N, B, K, R", standard,
               "no rest of this triad measured: `turncal noise` on a rest recording (hours for "
               "B, K and R), or turncald's {\"cmd\":\"noise\"} during a rest; give it with "
               "--noise");
  }
}

void AddWarmUp(Builder* b, const nlohmann::json& axes, const std::string& triad,
               const std::string& key, const std::string& standard, double factor,
               const std::string& unit, const std::string& source) {
  bool any = false;
  for (const auto& a : axes) {
    if (a.value("triad", "") != key) continue;
    const nlohmann::json& w = a.value("warm_up", nlohmann::json::object());
    if (!w.value("ok", false)) continue;
    any = true;
    if (w.value("resolved", false)) {
      b->Measured(triad, "warm-up time", standard, a.value("axis", ""), w.value("time_s", 0.0),
                  w.value("time_sigma_s", 0.0), "s",
                  fmt::format("{}: transient {:.3g} {} with tau {:.0f} s, to the Allan floor "
                              "{:.3g} {}",
                              AxisSource(a, source), w.value("amplitude", 0.0) * factor, unit,
                              w.value("tau_s", 0.0), w.value("threshold", 0.0) * factor, unit));
    } else {
      b->Interval(triad, "warm-up time", standard, a.value("axis", ""), 0.0, 0.0, 0.0, false, "s",
                  fmt::format("{}: no transient from the first sample (amplitude {:.2g} +- "
                              "{:.2g} {}): warm at the start, or the recording began after "
                              "switch-on",
                              AxisSource(a, source), w.value("amplitude", 0.0) * factor,
                              w.value("amplitude_sigma", 0.0) * factor, unit));
    }
  }
  if (!any) {
    b->Missing(triad, "warm-up time", standard,
               "no rest recording from switch-on: record the rest from power-on (`turncal "
               "capture`, then `turncal noise`) and give it with --noise");
  }
}

// The latest estimate of a triad (by time, else the last given) and every session's.
struct TriadEstimates {
  std::vector<Estimate> all;
  const Estimate* latest = nullptr;
};

void Accelerometer(Builder* b, const TriadEstimates& t, const nlohmann::json& noise,
                   const std::string& noise_source) {
  const std::string triad = "accelerometer";
  const double to_mg = 1e3 / kG;
  if (!t.latest) {
    for (const char* item : {"bias (K0)", "scale factor (K1)", "misalignment"})
      b->Missing(triad, item, "IEEE 1293",
                 "no accelerometer calibration given (a turntable session's accel12/accel13/"
                 "accel15, or free mode's accel9)");
  } else {
    const Estimate& e = *t.latest;
    AddTriplet(b, e, triad, "bias (K0)", "IEEE 1293", {{"bx", "by", "bz"}, {"x", "y", "z"}}, to_mg,
               "mg");
    if (e.free) {
      AddTriplet(b, e, triad, "scale-factor error (K1 / nominal - 1)", "IEEE 1293",
                 {{"kx", "ky", "kz"}, {"x", "y", "z"}, 1.0}, 1e6, "ppm");
      AddTriplet(b, e, triad, "misalignment (axis to the frame)", "IEEE 1293",
                 {{"m_yz", "m_zy", "m_zx"}, {"yz", "zy", "zx"}}, 1e3, "mrad");
    } else {
      AddTurntableGeometry(b, e, triad, "scale-factor error (K1)", "IEEE 1293");
    }
    if (e.Param("K2x")) {
      // The output error K2 a^2 at 1 g, in ug per g^2.
      AddTriplet(b, e, triad, "second-order coefficient (K2)", "IEEE 1293",
                 {{"K2x", "K2y", "K2z"}, {"x", "y", "z"}}, kG * 1e6, "ug/g^2");
    } else {
      b->Missing(triad, "second-order coefficient (K2)", "IEEE 1293",
                 fmt::format("{} has no second-order term: calibrate with accel15 on a turntable "
                             "(the cube's +-1 g and 0 g poses carry it; its observability and "
                             "gate say whether a given pose set does)",
                             e.model));
    }
  }
  if (t.all.size() >= 2) {
    AddRepeatability(b, t.all, triad, "IEEE 1293", to_mg, "mg");
  } else {
    b->Missing(triad, "bias turn-on repeatability", "IEEE 1293",
               "one turn-on: give the calibrations of several sessions with the unit switched "
               "off between them (or see `turncal registry drift SERIAL`)");
  }
  AddNoise(b, noise, triad, "acc", "IEEE 952 Annex C (Allan variance)", noise_source);
  AddWarmUp(b, noise, triad, "acc", "IEEE 1293", to_mg, "mg", noise_source);
}

void Gyroscope(Builder* b, const TriadEstimates& t, const nlohmann::json& noise,
               const std::string& noise_source) {
  const std::string triad = "gyroscope";
  const double to_dph = kRadPerSToDegPerH;
  if (!t.latest) {
    for (const char* item : {"bias", "scale factor", "scale-factor non-linearity",
                             "scale-factor asymmetry", "g-sensitivity", "misalignment"})
      b->Missing(triad, item, "IEEE 952 / 1431",
                 "no gyroscope calibration given (a turntable session's gyro12/gyro21, or free "
                 "mode's gyro9/gyro9g)");
  } else {
    const Estimate& e = *t.latest;
    AddTriplet(b, e, triad, "bias", "IEEE 1431", {{"bx", "by", "bz"}, {"x", "y", "z"}}, to_dph,
               "deg/h");
    if (e.free) {
      AddTriplet(b, e, triad, "scale-factor error (nominal - 1)", "IEEE 1431",
                 {{"kx", "ky", "kz"}, {"x", "y", "z"}, 1.0}, 1e6, "ppm");
      AddTriplet(
          b, e, triad, "misalignment (to the accelerometer)", "IEEE 1431",
          {{"m_yz", "m_zy", "m_zx", "m_xz", "m_xy", "m_yx"}, {"yz", "zy", "zx", "xz", "xy", "yx"}},
          1e3, "mrad");
    } else {
      AddTurntableGeometry(b, e, triad, "scale-factor error", "IEEE 1431");
    }
    // g-sensitivity: gyro21's Bg_ij, gyro9g's gij, in deg/h per g.
    const char* const turntable_g[9] = {"Bg_xx", "Bg_xy", "Bg_xz", "Bg_yx", "Bg_yy",
                                        "Bg_yz", "Bg_zx", "Bg_zy", "Bg_zz"};
    const char* const free_g[9] = {"g11", "g12", "g13", "g21", "g22", "g23", "g31", "g32", "g33"};
    Triplet g;
    for (int i = 0; i < 9; ++i) {
      g.names.push_back(e.free ? free_g[i] : turntable_g[i]);
      g.axes.push_back(std::string(kAxes[i / 3]) + kAxes[i % 3]);
    }
    if (e.Param(g.names[0])) {
      AddTriplet(b, e, triad, "g-sensitivity", "IEEE 1431", g, to_dph * kG, "deg/h/g");
    } else {
      b->Missing(triad, "g-sensitivity", "IEEE 1431",
                 fmt::format("{} has no g-sensitivity: calibrate with gyro21 (turntable) or "
                             "gyro9g (free)",
                             e.model));
    }
    // Non-linearity and asymmetry from the rate segments of a turntable calibration.
    RateLinearity lin;
    if (!e.free) {
      protocol::CalibrationDocument doc;
      std::string error;
      if (protocol::ParseCalibrationDocument(*e.doc, &doc, &error)) {
        lin = AnalyzeCalibration(doc).linearity;
      }
    }
    if (lin.compared) {
      const double lo = lin.levels.front().rate_dps, hi = lin.levels.back().rate_dps;
      b->Measured(triad, "scale-factor non-linearity (change over the range)", "IEEE 1431", "",
                  lin.slope_per_dps * (hi - lo) * 1e6, lin.slope_sigma * (hi - lo) * 1e6, "ppm",
                  fmt::format("{}: {} rate segments at {} rates from {:.1f} to {:.1f} deg/s; the "
                              "linear fit's chi^2 {:.1f} with {} dof (p {:.2f})",
                              e.From(), lin.segments, lin.levels.size(), lo, hi, lin.chi2, lin.dof,
                              lin.p_value));
    } else {
      b->Missing(triad, "scale-factor non-linearity", "IEEE 1431",
                 "no rate steps at two or more rates: a turntable session with rate segments "
                 "(the sequence's rates, up and down)");
    }
    if (lin.has_asymmetry) {
      b->Measured(triad, "scale-factor asymmetry (positive - negative)", "IEEE 1431", "",
                  lin.asymmetry * 1e6, lin.asymmetry_sigma * 1e6, "ppm",
                  fmt::format("{}: rate segments of both signs", e.From()));
    } else {
      b->Missing(triad, "scale-factor asymmetry", "IEEE 1431",
                 "no rate steps of both signs: a turntable session turning both ways");
    }
  }
  if (t.all.size() >= 2) {
    AddRepeatability(b, t.all, triad, "IEEE 1431", to_dph, "deg/h");
  } else {
    b->Missing(triad, "bias turn-on repeatability", "IEEE 1431",
               "one turn-on: give the calibrations of several sessions with the unit switched "
               "off between them (or see `turncal registry drift SERIAL`)");
  }
  AddNoise(b, noise, triad, "gyr", "IEEE 952 Annex C (Allan variance)", noise_source);
  AddWarmUp(b, noise, triad, "gyr", "IEEE 1431 (warm-up time)", to_dph, "deg/h", noise_source);
}

}  // namespace

int Characterisation::measured() const {
  return static_cast<int>(
      std::count_if(rows.begin(), rows.end(), [](const auto& r) { return r.measured; }));
}
int Characterisation::not_measured() const { return static_cast<int>(rows.size()) - measured(); }

bool Characterise(const CharacterisationInput& input, Characterisation* out, std::string* error) {
  Characterisation c;
  c.generated_utc = input.generated_utc;
  if (input.calibrations.empty() && input.noise_axes.empty()) {
    *error = "nothing to characterise: give calibrations and/or a rest measurement";
    return false;
  }
  std::map<std::string, TriadEstimates> triads;
  for (std::size_t i = 0; i < input.calibrations.size(); ++i) {
    const nlohmann::json& doc = input.calibrations[i];
    const std::string source =
        i < input.calibration_sources.size() ? input.calibration_sources[i] : "";
    if (!doc.is_object() || !doc.contains("model") || !doc["model"].is_string()) {
      *error = fmt::format("{}: not a calibration (no \"model\")", source);
      return false;
    }
    const std::string device = doc.value("device", "");
    if (!device.empty()) {
      if (!c.device.empty() && device != c.device) {
        *error = fmt::format("{}: device '{}', but the others are '{}'", source, device, c.device);
        return false;
      }
      c.device = device;
    }
    if (doc.contains("ok") && !doc.value("ok", false)) continue;  // a free model that failed
    Estimate e;
    e.doc = &doc;
    e.source = source;
    e.model = doc["model"].get<std::string>();
    e.time = doc.value("time", "");
    e.free = IsFree(doc);
    const std::string triad = TriadOfModel(e.model);
    if (triad.empty()) continue;
    if (e.model == "accmag") continue;  // its accelerometer part repeats accel9's
    triads[triad].all.push_back(e);
  }
  for (auto& [name, t] : triads) {
    // Per session (source) the last; the latest of them by time, else the last given.
    std::map<std::string, Estimate> per_source;
    for (const Estimate& e : t.all) per_source[e.source] = e;
    t.all.clear();
    for (const auto& [source, e] : per_source) t.all.push_back(e);
    std::stable_sort(t.all.begin(), t.all.end(),
                     [](const Estimate& a, const Estimate& b) { return a.time < b.time; });
    t.latest = &t.all.back();
  }
  for (const std::string& s : input.calibration_sources) {
    const std::string line = "calibration: " + s;
    if (std::find(c.sources.begin(), c.sources.end(), line) == c.sources.end())
      c.sources.push_back(line);
  }
  std::string noise_source = "rest";
  if (!input.noise_sources.empty()) {
    noise_source.clear();
    for (const std::string& s : input.noise_sources) {
      c.sources.push_back("rest: " + s);
      noise_source += (noise_source.empty() ? "" : ", ") + Base(s);
    }
  }
  Builder b(&c);
  Accelerometer(&b, triads["accelerometer"], input.noise_axes, noise_source);
  Gyroscope(&b, triads["gyroscope"], input.noise_axes, noise_source);
  bool mag_noise = false;
  for (const auto& a : input.noise_axes) mag_noise |= a.value("triad", "") == "mag";
  if (mag_noise) {
    AddNoise(&b, input.noise_axes, "magnetometer", "mag", "IEEE 952 Annex C (Allan variance)",
             noise_source);
    AddWarmUp(&b, input.noise_axes, "magnetometer", "mag", "(as IEEE 1431's)", 1e3, "mG",
              noise_source);
  }
  *out = std::move(c);
  return true;
}

}  // namespace turncal::report
