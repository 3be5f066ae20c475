#include "protocol/observability_json.h"

#include <fmt/format.h>

#include <cmath>

#include "core/frames/units.h"

namespace turncal {

namespace {

nlohmann::json Number(double v) { return std::isfinite(v) ? nlohmann::json(v) : nullptr; }

nlohmann::json ByName(const std::vector<std::string>& names, const Eigen::VectorXd& values) {
  nlohmann::json out = nlohmann::json::object();
  for (std::size_t i = 0; i < names.size(); ++i)
    out[names[i]] = Number(values[static_cast<Eigen::Index>(i)]);
  return out;
}

std::vector<std::string> Names(const MeasurementModel& model) {
  std::vector<std::string> names;
  for (const auto& p : model.parameters()) names.push_back(p.name);
  return names;
}

nlohmann::json Directions(const std::vector<NamedDirection>& list, const MeasurementModel& model) {
  nlohmann::json out = nlohmann::json::array();
  for (const auto& d : list) out.push_back(ToJson(d, model));
  return out;
}

// The rank analysis's common keys, with the null directions as {NAME: coef} objects as DESIGN.md
// promises and the details alongside.
void AddAnalysis(const RankAnalysis& a, const MeasurementModel& model, nlohmann::json* j) {
  (*j)["rank"] = a.rank;
  (*j)["condition"] = Number(a.condition);
  (*j)["relative_singular_values"] = std::vector<double>(
      a.relative_singular.data(), a.relative_singular.data() + a.relative_singular.size());
  nlohmann::json coefficients = nlohmann::json::array();
  for (const auto& d : a.null) coefficients.push_back(ToJson(d, model)["coefficients"]);
  (*j)["null_directions"] = coefficients;
  (*j)["null_direction_details"] = Directions(a.null, model);
  (*j)["weak_directions"] = Directions(a.weak, model);
}

}  // namespace

nlohmann::json ToJson(const NamedDirection& d, const MeasurementModel& model) {
  nlohmann::json coefficients = nlohmann::json::object();
  const auto& params = model.parameters();
  for (std::size_t i = 0; i < params.size(); ++i) {
    const double c = d.coefficients[static_cast<Eigen::Index>(i)];
    if (std::abs(c) >= 1e-4) coefficients[params[i].name] = c;
  }
  return {{"coefficients", coefficients},
          {"text", d.text},
          {"involved", d.involved},
          {"relative_singular_value", d.relative_singular_value}};
}

nlohmann::json ToJson(const StructuralReport& r, const MeasurementModel& model) {
  nlohmann::json j = {{"analysis", "structural"},
                      {"model", r.model},
                      {"params", r.params},
                      {"extended_params", r.extended},
                      {"point", ByName(Names(model), r.theta)}};
  AddAnalysis(r.analysis, model, &j);
  return j;
}

nlohmann::json ToJson(const PoseDiversity& d) {
  return {{"poses", d.poses},
          {"regressor_rank", d.regressor_rank},
          {"regressor_rank_of", 10},
          {"regressor_min_singular", d.regressor_min_singular},
          {"distinct_down_directions", d.distinct_down},
          {"down_scatter_eigenvalues", {d.down_scatter[0], d.down_scatter[1], d.down_scatter[2]}},
          {"findings", d.findings}};
}

nlohmann::json ToJson(const DataReport& r, const MeasurementModel& model) {
  nlohmann::json j = {{"analysis", "data"},
                      {"model", r.model},
                      {"params", r.params},
                      {"poses", r.poses},
                      {"expected_rank", r.expected_rank},
                      {"point", ByName(Names(model), r.theta)},
                      {"sigma", ByName(Names(model), r.sigma)},
                      {"diversity", ToJson(r.diversity)}};
  if (!r.gauge.empty()) j["gauge"] = r.gauge;
  AddAnalysis(r.analysis, model, &j);
  return j;
}

nlohmann::json ToJson(const GateResult& g) {
  return {{"pass", g.pass}, {"reasons", g.reasons}, {"missing", g.missing}, {"notes", g.notes}};
}

nlohmann::json ToJson(const NextPoseAdvice& a) {
  nlohmann::json j = {{"class", "NEXT_POSE"}, {"ok", a.ok}};
  if (!a.ok) {
    j["error"] = a.error;
    return j;
  }
  j["criterion"] = fmt::format(
      "D-optimal: largest increase of sum over models of log det(Fisher information){}{}",
      a.objective == PlanObjective::kTime ? " per second of table time" : " per pose",
      a.drift_aware ? ", each pose's information given the earlier ones under the drift model"
                    : "");
  j["objective"] = ToString(a.objective);
  j["candidates"] = a.candidates;
  j["pose"] = ToJson(a.pose);
  j["gain"] = a.gain;
  j["seconds"] = a.seconds;
  nlohmann::json top = nlohmann::json::array();
  for (const auto& c : a.top) {
    top.push_back({{"pose", ToJson(c.pose)},
                   {"gain", c.gain},
                   {"seconds", c.seconds},
                   {"score", c.score},
                   {"model_gains", c.model_gains},
                   {"move", c.move}});
  }
  j["top"] = top;
  nlohmann::json models = nlohmann::json::array();
  for (const auto& m : a.models) {
    nlohmann::json o = {{"model", m.model},
                        {"sigma_now", ByName(m.names, m.sigma_now)},
                        {"shortfalls_after", m.shortfalls_after},
                        {"gauge_blocks_gate", m.gauge_blocks}};
    if (m.sigma_after.size() > 0) o["sigma_after"] = ByName(m.names, m.sigma_after);
    if (m.sigma_planned.size() > 0) o["sigma_planned"] = ByName(m.names, m.sigma_planned);
    o["captured"] = {{"poses", m.captured_poses},
                     {"rate_segments", m.captured_rate_segments},
                     {"moves", m.captured_moves}};
    o["planned"] = {{"poses", m.planned_poses},
                    {"rate_segments", m.planned_rate_segments},
                    {"moves", m.planned_moves}};
    models.push_back(o);
  }
  j["models"] = models;
  j["poses_to_gate"] = a.poses_to_gate;
  j["seconds_to_gate"] = a.seconds_to_gate;
  nlohmann::json plan = nlohmann::json::array();
  for (const auto& p : a.continuation) plan.push_back(ToJson(p));
  j["plan"] = plan;
  j["plan_seconds"] = a.continuation_seconds;
  return j;
}

}  // namespace turncal
