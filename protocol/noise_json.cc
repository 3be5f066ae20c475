#include "protocol/noise_json.h"

#include <cmath>

namespace turncal {

namespace {

nlohmann::json Interval(const VarianceInterval& v) {
  return nlohmann::json::array({v.low, v.high});
}

// The IEEE 952 terms: each with its value, sigma, 95 % interval and whether it is resolved, in SI
// and in the datasheet's unit.
nlohmann::json IeeeJson(const std::string& triad, const IeeeNoiseFit& fit) {
  if (!fit.ok) return {{"ok", false}, {"error", fit.error}};
  nlohmann::json j = {
      {"ok", true},           {"chi2", fit.chi2},           {"dof", fit.dof},
      {"points", fit.points}, {"tau_min_s", fit.tau_min_s}, {"tau_max_s", fit.tau_max_s}};
  for (int k = 0; k < kIeeeTerms; ++k) {
    const IeeeTermEstimate& e = fit.terms[static_cast<std::size_t>(k)];
    const IeeeUnit u = IeeeTermUnit(triad, k);
    const double f = u.to_datasheet;
    j[IeeeTermName(k)] = {{"value", e.value},
                          {"sigma", e.sigma},
                          {"ci95", {e.low95, e.high95}},
                          {"resolved", e.resolved},
                          {"unit", u.si},
                          {"datasheet",
                           {{"value", e.value * f},
                            {"sigma", e.sigma * f},
                            {"ci95", {e.low95 * f, e.high95 * f}},
                            {"unit", u.datasheet}}}};
  }
  return j;
}

// The warm-up transient from the first sample (core/analysis/warm_up.h).
nlohmann::json WarmUpJson(const WarmUpFit& w) {
  if (!w.ok) return {{"ok", false}, {"error", w.error}};
  nlohmann::json j = {{"ok", true},
                      {"resolved", w.resolved},
                      {"settled", w.settled},
                      {"settled_sigma", w.settled_sigma},
                      {"amplitude", w.amplitude},
                      {"amplitude_sigma", w.amplitude_sigma},
                      {"tau_s", w.tau_s},
                      {"tau_sigma_s", w.tau_sigma},
                      {"threshold", w.threshold},
                      {"bins", w.bins},
                      {"span_s", w.span_s},
                      {"modelled", w.modelled}};
  if (w.resolved) {
    j["time_s"] = w.time_s;
    j["time_sigma_s"] = w.time_sigma;
  }
  return j;
}

}  // namespace

nlohmann::json RestNoiseAxesJson(const std::vector<RestNoiseAxis>& results) {
  nlohmann::json out = nlohmann::json::array();
  for (const auto& r : results) {
    nlohmann::json points = nlohmann::json::array();
    for (const auto& p : r.points) {
      nlohmann::json j = {{"tau_s", p.tau_s},
                          {"m", p.m},
                          {"stride", p.stride},
                          {"adev", p.adev},
                          {"edf", p.edf},
                          {"alpha", p.alpha},
                          {"ci68", Interval(p.ci68)},
                          {"ci95", Interval(p.ci95)}};
      if (std::isfinite(p.hdev)) {
        j["hdev"] = p.hdev;
        j["hdev_edf"] = p.hedf;
        j["hdev_ci68"] = Interval(p.hci68);
        j["hdev_ci95"] = Interval(p.hci95);
      }
      points.push_back(std::move(j));
    }
    out.push_back({{"triad", r.triad},
                   {"axis", std::string(1, "xyz"[r.axis])},
                   {"unit", RestNoiseUnit(r.triad)},
                   {"samples", r.samples},
                   {"rate_hz", r.rate_hz},
                   {"gaps", r.gaps},
                   {"white_density", r.fit.white_density},
                   {"gauss_markov_sigma", r.fit.gm_sigma},
                   {"gauss_markov_tau_s", r.fit.gm_tau_s},
                   {"random_walk", r.fit.random_walk},
                   {"bias_instability", r.fit.bias_instability},
                   {"bias_instability_tau_s", r.fit.bias_instability_tau_s},
                   {"longest_tau_s", r.fit.longest_tau_s},
                   {"rms_log_error", r.fit.rms_log_error},
                   {"ieee", IeeeJson(r.triad, r.ieee)},
                   {"warm_up", WarmUpJson(r.warm_up)},
                   {"allan", points}});
  }
  return out;
}

}  // namespace turncal
