#pragma once
// What `turncal noise` gives beside its table (issue 39 item 2), from the axes' JSON (a file's
// analysis and a live one's alike, protocol/noise_json.h): the IEEE 952 terms' table, Kalibr's
// imu.yaml, and the [station] noise prior for turncald.toml.

#include <nlohmann/json.hpp>
#include <string>

namespace turncal::tools {

// The IEEE 952 terms of every axis in the datasheet's units, value +- sigma, or "< upper" for a
// term the recording cannot tell from zero.
std::string IeeeTermsText(const nlohmann::json& axes);
// Each axis's warm-up transient (RestNoiseAxesJson's "warm_up"), one line each.
std::string WarmUpText(const nlohmann::json& axes);

// Kalibr's imu.yaml: noise densities (IEEE N) and random walks (IEEE K) of the accelerometer and
// the gyroscope, the largest axis's, with the units and where each came from written beside
// them. Empty (and *error says why) without an accelerometer or gyroscope axis.
std::string KalibrImuYaml(const nlohmann::json& axes, const std::string& source,
                          const std::string& rostopic, std::string* error);

// turncald.toml's [station] noise prior (daemon/service/config.cc's keys) from the
// Gauss-Markov model fitted beside the IEEE terms. Empty (and *error) without an accelerometer
// or magnetometer axis.
std::string StationNoiseToml(const nlohmann::json& axes, const std::string& source,
                             std::string* error);

}  // namespace turncal::tools
