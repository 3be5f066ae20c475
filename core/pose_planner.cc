#include "core/pose_planner.h"

#include <fmt/format.h>

#include <Eigen/Cholesky>
#include <Eigen/LU>
#include <algorithm>
#include <cmath>

#include "core/mag22_gauge.h"
#include "core/units.h"

namespace turncal {

namespace {

bool AxisValid(const AxisRange& a, const char* name, std::string* error) {
  if (!std::isfinite(a.min_deg) || !std::isfinite(a.max_deg) || !std::isfinite(a.step_deg) ||
      a.max_deg < a.min_deg || a.step_deg < 0 || (a.step_deg == 0 && a.max_deg != a.min_deg)) {
    if (error) {
      *error =
          fmt::format("{} range: need min <= max and step > 0 (step 0 only when min = max)", name);
    }
    return false;
  }
  if (a.step_deg > 0 && (a.max_deg - a.min_deg) / a.step_deg > 3600) {
    if (error) *error = fmt::format("{} range: more than 3600 steps", name);
    return false;
  }
  return true;
}

std::vector<double> AxisValues(const AxisRange& a) {
  std::vector<double> v;
  if (a.step_deg <= 0) return {a.min_deg * kRadPerDeg};
  for (double x = a.min_deg; x <= a.max_deg + 1e-9; x += a.step_deg) v.push_back(x * kRadPerDeg);
  return v;
}

// One target's state during the greedy search, in scaled units.
struct TargetState {
  const PlanningTarget* target = nullptr;
  Eigen::VectorXd scales;
  Eigen::MatrixXd information;          // D F D + prior
  std::vector<Eigen::MatrixXd> cand_J;  // per candidate: W J D, 3 x N
  int poses = 0;
  bool gauge_blocks = false;

  Eigen::VectorXd Sigma() const {
    const MeasurementModel& model = *target->model;
    const int N = model.num_parameters();
    if (model.gauge_dimension() == 0) {
      const Eigen::MatrixXd cov = information.ldlt().solve(Eigen::MatrixXd::Identity(N, N));
      return scales.cwiseProduct(cov.diagonal().cwiseMax(0.0).cwiseSqrt());
    }
    const Eigen::MatrixXd F_raw =
        scales.cwiseInverse().asDiagonal() * information * scales.cwiseInverse().asDiagonal();
    const Eigen::MatrixXd B = Mag22GaugeTangentBasis(model, target->theta);
    const Eigen::MatrixXd inner = B.transpose() * F_raw * B;
    const Eigen::MatrixXd cov =
        B * inner.ldlt().solve(Eigen::MatrixXd::Identity(B.cols(), B.cols())) * B.transpose();
    return cov.diagonal().cwiseMax(0.0).cwiseSqrt();
  }

  bool Passes(const Eigen::VectorXd& sigma, std::vector<std::string>* shortfalls) const {
    const MeasurementModel& model = *target->model;
    *shortfalls = PrecisionShortfalls(model, sigma, target->gate);
    const int rank = model.num_parameters() - model.gauge_dimension();
    if (3 * poses - rank < target->gate.min_dof) {
      shortfalls->push_back(fmt::format("{} poses leave {} degrees of freedom; the gate needs {}",
                                        poses, 3 * poses - rank, target->gate.min_dof));
    }
    return shortfalls->empty() && !gauge_blocks;
  }
};

double LogDetGain(const Eigen::MatrixXd& J, const Eigen::LDLT<Eigen::MatrixXd>& information) {
  const Eigen::Matrix3d S =
      Eigen::Matrix3d::Identity() + J * information.solve(Eigen::MatrixXd(J.transpose()));
  return std::log(S.determinant());
}

}  // namespace

bool PoseGrid::IsValid(std::string* error) const {
  if (!AxisValid(phi, "phi", error) || !AxisValid(gamma, "gamma", error) ||
      !AxisValid(psi, "psi", error)) {
    return false;
  }
  const double n = static_cast<double>(AxisValues(phi).size()) * AxisValues(gamma).size() *
                   AxisValues(psi).size();
  if (n > kMaxCandidates) {
    if (error) {
      *error = fmt::format("the grid has {:.0f} candidate poses; at most {} (use coarser steps)", n,
                           kMaxCandidates);
    }
    return false;
  }
  return true;
}

std::vector<TablePose> PoseGrid::Candidates() const {
  std::vector<TablePose> out;
  for (double f : AxisValues(phi))
    for (double g : AxisValues(gamma))
      for (double p : AxisValues(psi)) out.push_back(TablePose{f, g, p});
  return out;
}

bool PlannerOptions::IsValid(std::string* error) const {
  if (!grid.IsValid(error)) return false;
  if (!(prior_sigma_scaled > 0) || !std::isfinite(prior_sigma_scaled)) {
    if (error) *error = "prior_sigma_scaled must be finite and > 0";
    return false;
  }
  if (horizon < 1 || top < 1) {
    if (error) *error = "horizon and top must be >= 1";
    return false;
  }
  return true;
}

NextPoseAdvice PlanNextPose(const std::vector<PlanningTarget>& targets,
                            const PlannerOptions& options) {
  NextPoseAdvice advice;
  if (!options.IsValid(&advice.error)) return advice;
  if (targets.empty()) {
    advice.error = "no model to plan for";
    return advice;
  }
  const std::vector<TablePose> candidates = options.grid.Candidates();
  advice.candidates = static_cast<int>(candidates.size());

  std::vector<TargetState> states(targets.size());
  for (std::size_t t = 0; t < targets.size(); ++t) {
    const PlanningTarget& target = targets[t];
    if (target.model == nullptr || target.theta.size() != target.model->num_parameters() ||
        !target.theta.allFinite() || !target.sqrt_information.allFinite()) {
      advice.error = fmt::format("planning target {} is incomplete", t);
      return advice;
    }
    if (!target.gate.IsValid(&advice.error)) return advice;
    const MeasurementModel& model = *target.model;
    TargetState& s = states[t];
    s.target = &target;
    s.scales = ParameterScales(model);
    const int N = model.num_parameters();
    const Eigen::MatrixXd J =
        WhitenedJacobian(model, target.theta, target.captured) * s.scales.asDiagonal();
    s.information =
        J.transpose() * J +
        Eigen::MatrixXd::Identity(N, N) / (options.prior_sigma_scaled * options.prior_sigma_scaled);
    s.poses = static_cast<int>(target.captured.size());
    Jacobian3 Ji;
    s.cand_J.reserve(candidates.size());
    for (const auto& c : candidates) {
      model.Predict(target.theta, c, &Ji);
      s.cand_J.push_back(target.sqrt_information * Ji * s.scales.asDiagonal());
    }
    const Eigen::MatrixXd gauge = GaugeDirections(model, target.theta);
    if (gauge.cols() > 0 && !target.gate.accept_gauge_dependent_correction) {
      for (int j : GatedParameters(model)) {
        if (gauge.row(j).cwiseAbs().maxCoeff() > 1e-12) s.gauge_blocks = true;
      }
    }
  }

  auto all_pass = [&]() {
    bool pass = true;
    std::vector<std::string> shortfalls;
    for (const auto& s : states) pass = s.Passes(s.Sigma(), &shortfalls) && pass;
    return pass;
  };
  for (const auto& s : states) {
    ModelOutlook o;
    o.model = s.target->model->name();
    for (const auto& p : s.target->model->parameters()) o.names.push_back(p.name);
    o.sigma_now = s.Sigma();
    o.gauge_blocks = s.gauge_blocks;
    advice.models.push_back(o);
  }
  if (all_pass()) advice.poses_to_gate = 0;
  const bool blocked = std::any_of(states.begin(), states.end(),
                                   [](const TargetState& s) { return s.gauge_blocks; });

  for (int step = 0; step < options.horizon; ++step) {
    std::vector<Eigen::LDLT<Eigen::MatrixXd>> factors;
    for (const auto& s : states) factors.emplace_back(s.information);
    std::vector<CandidateScore> scores(candidates.size());
    for (std::size_t c = 0; c < candidates.size(); ++c) {
      scores[c].pose = candidates[c];
      for (std::size_t t = 0; t < states.size(); ++t) {
        const double g = LogDetGain(states[t].cand_J[c], factors[t]);
        scores[c].model_gains.push_back(g);
        scores[c].gain += g;
      }
    }
    std::size_t best = 0;
    for (std::size_t c = 1; c < scores.size(); ++c)
      if (scores[c].gain > scores[best].gain) best = c;
    if (step == 0) {
      std::vector<std::size_t> order(scores.size());
      for (std::size_t i = 0; i < order.size(); ++i) order[i] = i;
      const auto k = std::min<std::size_t>(static_cast<std::size_t>(options.top), order.size());
      std::partial_sort(order.begin(), order.begin() + static_cast<std::ptrdiff_t>(k), order.end(),
                        [&](std::size_t a, std::size_t b) {
                          return scores[a].gain > scores[b].gain ||
                                 (scores[a].gain == scores[b].gain && a < b);
                        });
      for (std::size_t i = 0; i < k; ++i) advice.top.push_back(scores[order[i]]);
      advice.pose = candidates[best];
      advice.gain = scores[best].gain;
    }
    for (auto& s : states) {
      s.information += s.cand_J[best].transpose() * s.cand_J[best];
      ++s.poses;
    }
    if (step == 0) {
      for (std::size_t t = 0; t < states.size(); ++t) {
        advice.models[t].sigma_after = states[t].Sigma();
        states[t].Passes(advice.models[t].sigma_after, &advice.models[t].shortfalls_after);
      }
    }
    // Already passing, or never passing (a gauge blocks the gate): only the recommendation.
    if (advice.poses_to_gate == 0 || blocked) break;
    advice.continuation.push_back(candidates[best]);
    if (all_pass()) {
      advice.poses_to_gate = step + 1;
      break;
    }
  }
  advice.ok = true;
  return advice;
}

}  // namespace turncal
