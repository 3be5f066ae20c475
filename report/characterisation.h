#pragma once
// The IEEE test report (issue 39 item 4; `turncal characterise`): what the standards ask a lab
// to measure of an accelerometer (IEEE Std 1293: bias K0, scale factor K1, the second-order
// coefficient K2, misalignment, noise) and of a gyroscope (IEEE Std 952 and 1431: bias, its
// turn-on repeatability, scale factor, its non-linearity and asymmetry, g-sensitivity,
// misalignment, the Allan terms Q N B K R, warm-up time), laid out item by item with what this
// session measured and its expanded uncertainty U (k = 2) -- or, for what it could not measure,
// why not and what would measure it. Nothing is left out silently.
//
// The inputs are documents turncal already writes: calibrations (a turntable session's
// calibrations/DEVICE.MODEL.json, a free one's, or `turncal free --json`'s models), several
// sessions' for the turn-on repeatability, and a rest measurement's axes (`turncal noise --json`,
// turncald's rest_noise/ files: the IEEE terms and the warm-up). Pure computation over JSON.

#include <nlohmann/json.hpp>
#include <string>
#include <vector>

namespace turncal::report {

struct CharacterisationInput {
  // One entry per model estimate: a calibration document, or one of `turncal free --json`'s
  // "models" (the caller splits them). Several of one triad from different sessions give the
  // turn-on repeatability; the latest (by "time", else the last given) is the session's value.
  std::vector<nlohmann::json> calibrations;
  std::vector<std::string> calibration_sources;  // per entry, shown in the report
  // Rest measurements' axes (RestNoiseAxesJson), concatenated; empty: no noise measured.
  nlohmann::json noise_axes = nlohmann::json::array();
  std::vector<std::string> noise_sources;
  std::string generated_utc;  // shown as given
};

// One item of the report: an axis's (or the triad's) figure with U (k = 2), an interval where
// the figure is one-sided or skewed, or why it is not measured.
struct CharacteristicRow {
  std::string triad;     // "accelerometer" | "gyroscope" | "magnetometer"
  std::string item;      // "bias (K0)", "turn-on repeatability", ...
  std::string standard;  // "IEEE 1293 §..."
  std::string axis;      // "x" | "y" | "z" | "xy" ... | "" (the triad)
  bool measured = false;
  double value = 0.0, u95 = 0.0;  // U = 2 sigma; 0 when only the interval means something
  bool upper_bound = false;       // the value is a 95 % upper bound (not resolved)
  bool has_interval = false;
  double low95 = 0.0, high95 = 0.0;
  std::string unit;
  std::string from;  // where it came from; or why it is not measured and what would measure it
};

struct Characterisation {
  std::string device;
  std::vector<CharacteristicRow> rows;
  std::vector<std::string> sources;
  std::string generated_utc;
  int measured() const;
  int not_measured() const;
};

// False with a message when there is nothing to characterise (no calibration and no noise), a
// calibration names no model, or two name different devices.
bool Characterise(const CharacterisationInput& input, Characterisation* out, std::string* error);

nlohmann::json ToJson(const Characterisation& c);
// A self-contained HTML page (inline CSS, no script): one table per triad, the items not
// measured greyed with their reason, and the list of them at the end.
std::string CharacterisationHtml(const Characterisation& c);
// The same as plain text for a terminal.
std::string CharacterisationText(const Characterisation& c);

}  // namespace turncal::report
