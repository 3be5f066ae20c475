#include "core/planning/pose_planner.h"

#include <fmt/format.h>

#include <Eigen/Cholesky>
#include <Eigen/LU>
#include <algorithm>
#include <cmath>

#include "core/frames/units.h"
#include "core/modeling/mag22_gauge.h"
#include "core/planning/drift_design.h"

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
  Eigen::MatrixXd information;          // D F D + prior (absolute wander with drift)
  std::vector<Eigen::MatrixXd> cand_J;  // per candidate: J D, 3 x N (whitened without drift)
  int poses = 0;
  bool gauge_blocks = false;
  // With drift: the poses in time order, captured then planned, and the clock.
  std::optional<DriftDesign> design;
  Eigen::Vector3d new_white = Eigen::Vector3d::Ones();  // a planned pose's white variance
  double t_now_s = 0.0;  // the end of the latest window on the target's clock
  Eigen::MatrixXd prior;

  void Refresh() {
    if (design) information = design->Information() + prior;
  }

  // The rows a candidate would add when its dwell starts `lead_s` after t_now_s.
  Eigen::MatrixXd Rows(std::size_t c, double lead_s, double dwell_s) const {
    if (!design) return cand_J[c];
    const TimeWindow w{t_now_s + lead_s, t_now_s + lead_s + dwell_s};
    return design->InnovationRows(cand_J[c], new_white, w);
  }

  void Append(std::size_t c, double lead_s, double dwell_s) {
    ++poses;
    if (!design) {
      information += cand_J[c].transpose() * cand_J[c];
      return;
    }
    const TimeWindow w{t_now_s + lead_s, t_now_s + lead_s + dwell_s};
    design->Add(cand_J[c], new_white, w);
    t_now_s = w.t1_s;
    Refresh();
  }

  Eigen::VectorXd Sigma() const {
    const MeasurementModel& model = *target->model;
    const int N = model.num_parameters();
    // The gate judges the bias over the latest window (the calibrator's parametrisation).
    const Eigen::MatrixXd F = design && design->size() > 0
                                  ? Eigen::MatrixXd(design->InformationAtLatest() + prior)
                                  : information;
    if (model.gauge_dimension() == 0) {
      const Eigen::MatrixXd cov = F.ldlt().solve(Eigen::MatrixXd::Identity(N, N));
      return scales.cwiseProduct(cov.diagonal().cwiseMax(0.0).cwiseSqrt());
    }
    const Eigen::MatrixXd F_raw =
        scales.cwiseInverse().asDiagonal() * F * scales.cwiseInverse().asDiagonal();
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

// The diagonal of the covariance whose inverse square root is `sqrt_information`.
Eigen::Vector3d WhiteVariance(const Eigen::Matrix3d& sqrt_information) {
  const Eigen::Matrix3d info = sqrt_information.transpose() * sqrt_information;
  return info.inverse().diagonal().cwiseMax(1e-300);
}

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

const char* ToString(PlanObjective objective) {
  switch (objective) {
    case PlanObjective::kTime:
      return "time";
    case PlanObjective::kPoses:
      return "poses";
  }
  return "?";
}

bool PlannerOptions::IsValid(std::string* error) const {
  if (!grid.IsValid(error) || !motion.IsValid(error)) return false;
  if (!(dwell_s > 0) || !std::isfinite(dwell_s)) {
    if (error) *error = "the planned dwell must be finite and > 0";
    return false;
  }
  if (!(prior_sigma_scaled > 0) || !std::isfinite(prior_sigma_scaled)) {
    if (error) *error = "prior_sigma_scaled must be finite and > 0";
    return false;
  }
  if (horizon < 1 || top < 1 || min_continuation < 0) {
    if (error) *error = "horizon and top must be >= 1, min_continuation >= 0";
    return false;
  }
  return true;
}

PlanningTarget TargetFromCalibrator(const Calibrator& calibrator, const Eigen::VectorXd& theta,
                                    double dwell_s, const GateOptions& gate,
                                    const std::optional<Eigen::Vector3d>& sample_sigma,
                                    double rate_hz) {
  const CalibratorOptions& o = calibrator.options();
  PlanningTarget t;
  t.model = calibrator.model();
  t.theta = theta;
  t.drift = o.drift;
  if (o.drift.enabled()) {
    calibrator.planning_poses(&t.captured, &t.captured_windows);
  } else {
    t.captured = calibrator.weighted_poses();
  }
  t.gate = gate;
  Eigen::Vector3d white =
      Eigen::Vector3d::Constant(o.noise_density * o.noise_density / (2 * dwell_s));
  if (sample_sigma && rate_hz > 0) {
    white = white.cwiseMax(sample_sigma->cwiseAbs2() / (rate_hz * dwell_s));
  }
  if (!(white.minCoeff() > 0) && !t.captured_windows.empty()) {
    Eigen::Vector3d sum = Eigen::Vector3d::Zero();
    for (std::size_t i = 0; i < t.captured.size(); ++i) {
      sum += WhiteVariance(t.captured[i].sqrt_information) * t.captured_windows[i].duration_s() /
             dwell_s;
    }
    white = white.cwiseMax(sum / static_cast<double>(t.captured.size()));
  }
  if (!(white.minCoeff() > 0)) white = white.cwiseMax(o.drift.gm_sigma.cwiseAbs2());
  white.array() += o.pose_offset_sigma * o.pose_offset_sigma;
  if (!(white.minCoeff() > 0)) white.setOnes();  // no noise model at all: the planner's scale
  t.sqrt_information = white.cwiseSqrt().cwiseInverse().asDiagonal();
  return t;
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
  advice.objective = options.objective;

  std::vector<TargetState> states(targets.size());
  for (std::size_t t = 0; t < targets.size(); ++t) {
    const PlanningTarget& target = targets[t];
    const bool drift = target.drift.enabled();
    if (target.model == nullptr || target.theta.size() != target.model->num_parameters() ||
        !target.theta.allFinite() || !target.sqrt_information.allFinite() ||
        (drift && target.captured_windows.size() != target.captured.size())) {
      advice.error = fmt::format("planning target {} is incomplete", t);
      return advice;
    }
    if (!target.gate.IsValid(&advice.error)) return advice;
    if (drift && !target.drift.IsValid(&advice.error)) return advice;
    const MeasurementModel& model = *target.model;
    TargetState& s = states[t];
    s.target = &target;
    s.scales = ParameterScales(model);
    const int N = model.num_parameters();
    s.prior =
        Eigen::MatrixXd::Identity(N, N) / (options.prior_sigma_scaled * options.prior_sigma_scaled);
    s.poses = static_cast<int>(target.captured.size());
    Jacobian3 Ji;
    if (drift) {
      advice.drift_aware = true;
      s.design.emplace(target.drift, N);
      s.new_white = WhiteVariance(target.sqrt_information);
      for (int i : TimeOrder(target.captured_windows)) {
        const WeightedPose& p = target.captured[static_cast<std::size_t>(i)];
        model.Predict(target.theta, p.pose, &Ji);
        s.design->Add(Ji * s.scales.asDiagonal(), WhiteVariance(p.sqrt_information),
                      target.captured_windows[static_cast<std::size_t>(i)]);
        s.t_now_s = std::max(s.t_now_s, target.captured_windows[static_cast<std::size_t>(i)].t1_s);
      }
      s.Refresh();
    } else {
      const Eigen::MatrixXd J =
          WhitenedJacobian(model, target.theta, target.captured) * s.scales.asDiagonal();
      s.information = J.transpose() * J + s.prior;
    }
    s.cand_J.reserve(candidates.size());
    for (const auto& c : candidates) {
      model.Predict(target.theta, c, &Ji);
      s.cand_J.push_back(
          drift ? Eigen::MatrixXd(Ji * s.scales.asDiagonal())
                : Eigen::MatrixXd(target.sqrt_information * Ji * s.scales.asDiagonal()));
    }
    const Eigen::MatrixXd gauge = GaugeDirections(model, target.theta);
    if (gauge.cols() > 0 && !target.gate.accept_gauge_dependent_correction) {
      for (int j : GatedParameters(model)) {
        if (gauge.row(j).cwiseAbs().maxCoeff() > 1e-12) s.gauge_blocks = true;
      }
    }
  }

  // Where the table is: as told, else the first target's latest captured pose.
  TablePose at;
  if (options.table_at) {
    at = *options.table_at;
  } else if (const PlanningTarget& first = targets.front(); !first.captured.empty()) {
    at = first.captured.back().pose;
    if (first.captured_windows.size() == first.captured.size()) {
      at = first.captured[static_cast<std::size_t>(TimeOrder(first.captured_windows).back())].pose;
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

  double planned_s = 0.0;
  for (int step = 0; step < options.horizon; ++step) {
    std::vector<Eigen::LDLT<Eigen::MatrixXd>> factors;
    for (const auto& s : states) factors.emplace_back(s.information);
    std::vector<CandidateScore> scores(candidates.size());
    for (std::size_t c = 0; c < candidates.size(); ++c) {
      CandidateScore& sc = scores[c];
      sc.pose = candidates[c];
      const double lead_s = options.motion.MoveSeconds(at, candidates[c]) + options.motion.settle_s;
      sc.seconds = lead_s + options.dwell_s;
      for (std::size_t t = 0; t < states.size(); ++t) {
        const double g = LogDetGain(states[t].Rows(c, lead_s, options.dwell_s), factors[t]);
        sc.model_gains.push_back(g);
        sc.gain += g;
      }
      sc.score = options.objective == PlanObjective::kTime ? sc.gain / sc.seconds : sc.gain;
    }
    std::size_t best = 0;
    for (std::size_t c = 1; c < scores.size(); ++c)
      if (scores[c].score > scores[best].score) best = c;
    if (step == 0) {
      std::vector<std::size_t> order(scores.size());
      for (std::size_t i = 0; i < order.size(); ++i) order[i] = i;
      const auto k = std::min<std::size_t>(static_cast<std::size_t>(options.top), order.size());
      std::partial_sort(order.begin(), order.begin() + static_cast<std::ptrdiff_t>(k), order.end(),
                        [&](std::size_t a, std::size_t b) {
                          return scores[a].score > scores[b].score ||
                                 (scores[a].score == scores[b].score && a < b);
                        });
      for (std::size_t i = 0; i < k; ++i) advice.top.push_back(scores[order[i]]);
      advice.pose = candidates[best];
      advice.gain = scores[best].gain;
      advice.seconds = scores[best].seconds;
    }
    const double lead_s = scores[best].seconds - options.dwell_s;
    for (auto& s : states) s.Append(best, lead_s, options.dwell_s);
    at = candidates[best];
    if (step == 0) {
      for (std::size_t t = 0; t < states.size(); ++t) {
        advice.models[t].sigma_after = states[t].Sigma();
        states[t].Passes(advice.models[t].sigma_after, &advice.models[t].shortfalls_after);
      }
    }
    // Already passing, or never passing (a gauge blocks the gate): only the recommendation.
    if (advice.poses_to_gate == 0 || blocked) break;
    advice.continuation.push_back(candidates[best]);
    advice.continuation_seconds.push_back(scores[best].seconds);
    planned_s += scores[best].seconds;
    if (advice.poses_to_gate < 0 && all_pass()) {
      advice.poses_to_gate = step + 1;
      advice.seconds_to_gate = planned_s;
    }
    if (advice.poses_to_gate > 0 && step + 1 >= options.min_continuation) break;
  }
  if (advice.poses_to_gate == 0) advice.seconds_to_gate = 0.0;
  advice.ok = true;
  return advice;
}

}  // namespace turncal
