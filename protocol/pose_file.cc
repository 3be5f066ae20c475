#include "protocol/pose_file.h"

#include <fmt/format.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdlib>
#include <nlohmann/json.hpp>
#include <sstream>

#include "core/frames/units.h"
#include "protocol/pose_json.h"

namespace turncal {

namespace {

bool FromDegrees(double phi, double gamma, double psi, TablePose* out) {
  if (!std::isfinite(phi) || !std::isfinite(gamma) || !std::isfinite(psi)) return false;
  *out = TablePose{phi * kRadPerDeg, gamma * kRadPerDeg, psi * kRadPerDeg};
  return true;
}

bool ParseJson(const std::string& text, std::vector<TablePose>* poses, std::string* error) {
  const nlohmann::json doc = nlohmann::json::parse(text, nullptr, /*allow_exceptions=*/false);
  if (doc.is_discarded()) {
    *error = "not valid JSON";
    return false;
  }
  const nlohmann::json* list = &doc;
  if (doc.is_object()) {
    if (!doc.contains("poses")) {
      *error = "a JSON object must hold a \"poses\" array";
      return false;
    }
    list = &doc["poses"];
  }
  if (!list->is_array()) {
    *error = "the poses must be a JSON array";
    return false;
  }
  for (std::size_t i = 0; i < list->size(); ++i) {
    const auto& e = (*list)[i];
    double a[3];
    bool ok = true;
    if (e.is_array() && e.size() == 3) {
      for (int k = 0; k < 3; ++k) {
        ok = ok && e[k].is_number();
        if (ok) a[k] = e[k].get<double>();
      }
    } else if (e.is_object()) {
      const char* keys[3][2] = {{"phi_deg", "phi"}, {"gamma_deg", "gamma"}, {"psi_deg", "psi"}};
      for (int k = 0; k < 3 && ok; ++k) {
        const auto it = e.contains(keys[k][0]) ? e.find(keys[k][0]) : e.find(keys[k][1]);
        ok = it != e.end() && it->is_number();
        if (ok) a[k] = it->get<double>();
      }
    } else {
      ok = false;
    }
    TablePose pose;
    if (ok && e.is_object() && (e.contains("rate_axis") || e.contains("rate_dps"))) {
      std::string why;
      if (!protocol::ParseTablePose(e, &pose, &why)) {
        *error = fmt::format("pose {} (counting from 0): {}", i, why);
        return false;
      }
      poses->push_back(pose);
      continue;
    }
    if (!ok || !FromDegrees(a[0], a[1], a[2], &pose)) {
      *error = fmt::format(
          "pose {} (counting from 0): need [phi, gamma, psi] or {{\"phi_deg\", \"gamma_deg\", "
          "\"psi_deg\"}} with finite numbers in degrees",
          i);
      return false;
    }
    poses->push_back(pose);
  }
  return true;
}

bool ParseCsv(const std::string& text, std::vector<TablePose>* poses, std::string* error) {
  std::istringstream in(text);
  std::string line;
  int number = 0;
  bool first_content = true;
  while (std::getline(in, line)) {
    ++number;
    const auto start = line.find_first_not_of(" \t\r");
    if (start == std::string::npos || line[start] == '#') continue;
    // A header: a first line whose first field is not a number.
    std::string first_field = line.substr(start, line.find_first_of(",; \t\r", start) - start);
    char* end = nullptr;
    std::strtod(first_field.c_str(), &end);
    const bool header = first_content && (first_field.empty() || *end != '\0');
    first_content = false;
    if (header) continue;
    std::string cleaned = line;
    std::replace(cleaned.begin(), cleaned.end(), ',', ' ');
    std::replace(cleaned.begin(), cleaned.end(), ';', ' ');
    std::istringstream fields(cleaned);
    double a[3];
    std::string axis, extra;
    double rate_dps = 0;
    TablePose pose;
    if (!(fields >> a[0] >> a[1] >> a[2]) || !FromDegrees(a[0], a[1], a[2], &pose)) {
      *error = fmt::format("line {}: need three finite numbers phi, gamma, psi in degrees: '{}'",
                           number, line);
      return false;
    }
    // A rate segment: two more fields, the turning axis and its rate in deg/s.
    if (fields >> axis) {
      if (!TableAxisFromString(axis, &pose.rate_axis) || !(fields >> rate_dps) ||
          !std::isfinite(rate_dps) || rate_dps == 0 || (fields >> extra)) {
        *error = fmt::format(
            "line {}: after phi, gamma, psi only a rate segment's axis (outer, middle, inner) and "
            "rate (deg/s, non-zero): '{}'",
            number, line);
        return false;
      }
      pose.rate_radps = rate_dps * kRadPerDeg;
    }
    poses->push_back(pose);
  }
  return true;
}

}  // namespace

bool ParsePoses(const std::string& text, std::vector<TablePose>* poses, std::string* error) {
  std::string local_error;
  std::string* err = error ? error : &local_error;
  poses->clear();
  const auto start = text.find_first_not_of(" \t\r\n");
  if (start == std::string::npos) {
    *err = "no poses";
    return false;
  }
  const bool ok = (text[start] == '[' || text[start] == '{') ? ParseJson(text, poses, err)
                                                             : ParseCsv(text, poses, err);
  if (ok && poses->empty()) {
    *err = "no poses";
    return false;
  }
  if (!ok) poses->clear();
  return ok;
}

}  // namespace turncal
