#pragma once
// A rest's noise analysis (core/analysis/rest_noise.h) as JSON: `turncal noise --json`'s "axes"
// and turncald's {"cmd":"noise"} answer. Per axis: triad, axis, unit, samples, rate_hz, gaps,
// the fitted model (white_density, gauss_markov_sigma, gauss_markov_tau_s, random_walk,
// bias_instability, bias_instability_tau_s, longest_tau_s, rms_log_error) and "allan": every
// cluster size with tau_s, m, stride, adev, edf, alpha, ci68, ci95 and, where the recording
// holds it, hdev, hdev_edf, hdev_ci68, hdev_ci95 (docs/NOISE.md).

#include <nlohmann/json.hpp>
#include <vector>

#include "core/analysis/rest_noise.h"

namespace turncal {

nlohmann::json RestNoiseAxesJson(const std::vector<RestNoiseAxis>& results);

}  // namespace turncal
