#include "core/planning/pose_planner.h"

#include <fmt/format.h>

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <Eigen/LU>
#include <algorithm>
#include <cmath>

#include "core/estimation/move_residual.h"
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

// The rows a record would add, in scaled units: whitened without drift; with drift unwhitened,
// with its white variance per axis (the drift design whitens it given the earlier records). No
// rows: the record tells the model nothing (a rate segment for an accelerometer).
struct PlannedRows {
  Eigen::MatrixXd J;
  Eigen::Vector3d white = Eigen::Vector3d::Ones();
};

// One target's state during the greedy search, in scaled units.
struct TargetState {
  const PlanningTarget* target = nullptr;
  bool gyro = false;
  Eigen::VectorXd scales;
  Eigen::MatrixXd information;    // D F D + prior (absolute wander with drift)
  std::vector<PlannedRows> cand;  // per candidate
  int records = 0;                // poses, rate segments and moves (3 rows each)
  int poses = 0, rate_segments = 0, moves = 0;
  bool gauge_blocks = false;
  // With drift: the records in time order, captured then planned, and the clock.
  std::optional<DriftDesign> design;
  double t_now_s = 0.0;  // the end of the latest window on the target's clock
  Eigen::MatrixXd prior;

  void Refresh() {
    if (design) information = design->Information() + prior;
  }

  // A record's rows when its window is `w`: its innovation given every earlier one with drift.
  Eigen::MatrixXd Rows(const PlannedRows& r, const TimeWindow& w) const {
    if (!design || r.J.rows() == 0) return r.J;
    return design->InnovationRows(r.J, r.white, w);
  }

  // Takes the record in; false when it has no rows.
  bool Append(const PlannedRows& r, const TimeWindow& w) {
    if (r.J.rows() == 0) return false;
    ++records;
    if (!design) {
      information += r.J.transpose() * r.J;
      return true;
    }
    design->Add(r.J, r.white, w);
    Refresh();
    return true;
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
    if (3 * records - rank < target->gate.min_dof) {
      shortfalls->push_back(fmt::format("{} records leave {} degrees of freedom; the gate needs {}",
                                        records, 3 * records - rank, target->gate.min_dof));
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
  if (J.rows() == 0) return 0.0;
  const Eigen::MatrixXd S = Eigen::MatrixXd::Identity(J.rows(), J.rows()) +
                            J * information.solve(Eigen::MatrixXd(J.transpose()));
  return std::log(S.determinant());
}

// Sigma^{-1/2} of a symmetric positive definite covariance.
Eigen::Matrix3d InverseSqrt(const Eigen::Matrix3d& covariance) {
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(0.5 * (covariance + covariance.transpose()));
  return eig.eigenvectors() *
         eig.eigenvalues().cwiseMax(1e-300).cwiseSqrt().cwiseInverse().asDiagonal() *
         eig.eigenvectors().transpose();
}

// A record's rows from its unwhitened Jacobian (3 x N, raw units) and white covariance.
PlannedRows MakeRows(const TargetState& s, const Jacobian3& J, const Eigen::Matrix3d& white) {
  PlannedRows r;
  if (s.design) {
    r.J = J * s.scales.asDiagonal();
    r.white = white.diagonal().cwiseMax(1e-300);
  } else {
    r.J = InverseSqrt(white) * J * s.scales.asDiagonal();
  }
  return r;
}

// What a candidate gives a target: a static pose's prediction, weighed like a dwell; a rate
// segment's for a gyroscope, weighed over its whole revolutions with the table's rate accuracy
// (as Calibrator::add_pose weighs it); nothing otherwise.
PlannedRows CandidateRows(const TargetState& s, const TablePose& pose, double dwell_s) {
  const PlanningTarget& t = *s.target;
  const MeasurementModel& model = *t.model;
  const int N = model.num_parameters();
  if (pose.is_rate() && !s.gyro) return PlannedRows{Eigen::MatrixXd(0, N), {}};
  Jacobian3 J;
  model.Predict(t.theta, pose, &J);
  const Eigen::Matrix3d info = t.sqrt_information.transpose() * t.sqrt_information;
  Eigen::Matrix3d white = info.inverse();
  if (pose.is_rate()) {
    const double offset = t.pose_offset_sigma * t.pose_offset_sigma;
    const double ratio = dwell_s / RateCaptureSeconds(pose.rate_radps, dwell_s);
    Eigen::Matrix3d noise = white - offset * Eigen::Matrix3d::Identity();
    noise = 0.5 * (noise + noise.transpose());
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(noise);
    const Eigen::Vector3d rate_q = model.context().mounting * pose.TableRate_q();
    white = eig.eigenvectors() * (eig.eigenvalues().cwiseMax(0.0) * ratio).asDiagonal() *
                eig.eigenvectors().transpose() +
            offset * Eigen::Matrix3d::Identity() +
            t.rate_accuracy * t.rate_accuracy * rate_q * rate_q.transpose();
  }
  return MakeRows(s, J, white);
}

// The move from static `from` to static `to` as the calibrator would weigh it (Calibrator::
// add_move: Qbar and the white covariance at the nominal parameters); no rows when the target
// credits no moves or the move cannot be formed.
PlannedRows MoveRows(const TargetState& s, const PlannerOptions& options, const TablePose& from,
                     const TablePose& to) {
  const PlanningTarget& t = *s.target;
  const MeasurementModel& model = *t.model;
  const MoveRecord record = PlannedMove(model, options.motion, from, to, options.move_rest_s);
  std::unique_ptr<MoveResidual> residual =
      record.block_s.empty()
          ? nullptr
          : MoveResidual::Make(model, record, model.nominal(), t.noise_density, nullptr);
  if (!residual) return PlannedRows{Eigen::MatrixXd(0, model.num_parameters()), {}};
  const Eigen::Matrix3d white = residual->white_covariance() + t.pose_offset_sigma *
                                                                   t.pose_offset_sigma *
                                                                   Eigen::Matrix3d::Identity();
  WeightedPose move;
  move.pose = to;
  move.raw_residual = std::move(residual);
  return MakeRows(s, RecordJacobian(model, t.theta, move), white);
}

Eigen::MatrixXd Stack(const Eigen::MatrixXd& a, const Eigen::MatrixXd& b) {
  if (a.rows() == 0) return b;
  if (b.rows() == 0) return a;
  Eigen::MatrixXd out(a.rows() + b.rows(), a.cols());
  out << a, b;
  return out;
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
  if (!grid.IsValid(error) || !motion.IsValid(error) || !rates.IsValid(error)) return false;
  if (!(dwell_s > 0) || !std::isfinite(dwell_s)) {
    if (error) *error = "the planned dwell must be finite and > 0";
    return false;
  }
  if (!(prior_sigma_scaled > 0) || !std::isfinite(prior_sigma_scaled)) {
    if (error) *error = "prior_sigma_scaled must be finite and > 0";
    return false;
  }
  if (!std::isfinite(move_rest_s) || move_rest_s < 0) {
    if (error) *error = "move_rest_s must be finite and >= 0";
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
  if (t.model && t.model->sensor() == SensorKind::kGyroscope) {
    t.noise_density = o.noise_density;
    t.rate_accuracy = o.rate_accuracy;
  }
  t.pose_offset_sigma = o.pose_offset_sigma;
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
  std::vector<TablePose> candidates = options.grid.Candidates();
  const std::size_t n_static = candidates.size();
  const bool any_gyro = std::any_of(targets.begin(), targets.end(), [](const PlanningTarget& t) {
    return t.model && t.model->sensor() == SensorKind::kGyroscope;
  });
  if (any_gyro && !options.rates.rates_dps.empty()) {
    const std::vector<double> held[3] = {
        AxisValues(options.grid.phi), AxisValues(options.grid.gamma), AxisValues(options.grid.psi)};
    const std::vector<TablePose> rates = RateCandidates(options.rates, options.motion, held);
    if (candidates.size() + rates.size() > static_cast<std::size_t>(kMaxCandidates)) {
      advice.error = fmt::format("{} static poses and {} rate segments; at most {} candidates",
                                 candidates.size(), rates.size(), kMaxCandidates);
      return advice;
    }
    candidates.insert(candidates.end(), rates.begin(), rates.end());
  }
  advice.candidates = static_cast<int>(candidates.size());
  advice.objective = options.objective;

  std::vector<TargetState> states(targets.size());
  for (std::size_t t = 0; t < targets.size(); ++t) {
    const PlanningTarget& target = targets[t];
    const bool drift = target.drift.enabled();
    if (target.model == nullptr || target.theta.size() != target.model->num_parameters() ||
        !target.theta.allFinite() || !target.sqrt_information.allFinite() ||
        !std::isfinite(target.noise_density) || !std::isfinite(target.pose_offset_sigma) ||
        !std::isfinite(target.rate_accuracy) ||
        (drift && target.captured_windows.size() != target.captured.size())) {
      advice.error = fmt::format("planning target {} is incomplete", t);
      return advice;
    }
    if (!target.gate.IsValid(&advice.error)) return advice;
    if (drift && !target.drift.IsValid(&advice.error)) return advice;
    const MeasurementModel& model = *target.model;
    TargetState& s = states[t];
    s.target = &target;
    s.gyro = model.sensor() == SensorKind::kGyroscope;
    s.scales = ParameterScales(model);
    const int N = model.num_parameters();
    s.prior =
        Eigen::MatrixXd::Identity(N, N) / (options.prior_sigma_scaled * options.prior_sigma_scaled);
    s.records = static_cast<int>(target.captured.size());
    for (const auto& p : target.captured) {
      ++(p.raw_residual ? s.moves : p.pose.is_rate() ? s.rate_segments : s.poses);
    }
    if (drift) {
      advice.drift_aware = true;
      s.design.emplace(target.drift, N);
      for (int i : TimeOrder(target.captured_windows)) {
        const WeightedPose& p = target.captured[static_cast<std::size_t>(i)];
        s.design->Add(RecordJacobian(model, target.theta, p) * s.scales.asDiagonal(),
                      WhiteVariance(p.sqrt_information),
                      target.captured_windows[static_cast<std::size_t>(i)]);
        s.t_now_s = std::max(s.t_now_s, target.captured_windows[static_cast<std::size_t>(i)].t1_s);
      }
      s.Refresh();
    } else {
      const Eigen::MatrixXd J =
          WhitenedJacobian(model, target.theta, target.captured) * s.scales.asDiagonal();
      s.information = J.transpose() * J + s.prior;
    }
    s.cand.reserve(candidates.size());
    for (const auto& c : candidates) s.cand.push_back(CandidateRows(s, c, options.dwell_s));
    const Eigen::MatrixXd gauge = GaugeDirections(model, target.theta);
    if (gauge.cols() > 0 && !target.gate.accept_gauge_dependent_correction) {
      for (int j : GatedParameters(model)) {
        if (gauge.row(j).cwiseAbs().maxCoeff() > 1e-12) s.gauge_blocks = true;
      }
    }
  }

  // Where the table is: as told, else the first target's latest captured pose. After a rate
  // segment it stands at the segment's attitude and no move into the next pose is credited.
  TablePose at;
  if (options.table_at) {
    at = *options.table_at;
  } else if (const PlanningTarget& first = targets.front(); !first.captured.empty()) {
    at = first.captured.back().pose;
    if (first.captured_windows.size() == first.captured.size()) {
      at = first.captured[static_cast<std::size_t>(TimeOrder(first.captured_windows).back())].pose;
    }
  }
  // No move into the next pose: the table is in a rate segment, or nothing was captured yet.
  bool no_move = options.move_from_table_at ? !*options.move_from_table_at
                                            : at.is_rate() || targets.front().captured.empty();
  if (at.is_rate()) at = AfterRateSegment(at, at);

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
    o.captured_poses = s.poses;
    o.captured_rate_segments = s.rate_segments;
    o.captured_moves = s.moves;
    advice.models.push_back(o);
  }
  if (all_pass()) advice.poses_to_gate = 0;
  const bool blocked = std::any_of(states.begin(), states.end(),
                                   [](const TargetState& s) { return s.gauge_blocks; });

  // A candidate's timing from where the table is: the seconds before its capture, the capture's
  // and the whole (a rate segment's spin-down included).
  struct Timing {
    double lead_s = 0.0, capture_s = 0.0, total_s = 0.0;
  };
  std::vector<Timing> timing(candidates.size());
  std::vector<std::vector<PlannedRows>> move_rows(states.size());
  double planned_s = 0.0;
  for (int step = 0; step < options.horizon; ++step) {
    std::vector<Eigen::LDLT<Eigen::MatrixXd>> factors;
    for (const auto& s : states) factors.emplace_back(s.information);
    for (std::size_t c = 0; c < candidates.size(); ++c) {
      Timing& tm = timing[c];
      if (candidates[c].is_rate()) {
        tm.total_s = RateSegmentSeconds(options.motion, options.rates, at, candidates[c],
                                        options.dwell_s, &tm.lead_s);
        tm.capture_s = RateCaptureSeconds(candidates[c].rate_radps, options.dwell_s);
      } else {
        tm.lead_s = options.motion.MoveSeconds(at, candidates[c]) + options.motion.settle_s;
        tm.capture_s = options.dwell_s;
        tm.total_s = tm.lead_s + tm.capture_s;
      }
    }
    // The moves into each static candidate, for the gyroscopes that credit them.
    for (std::size_t t = 0; t < states.size(); ++t) {
      move_rows[t].clear();
      const PlanningTarget& target = *states[t].target;
      if (!options.moves || no_move || !states[t].gyro || !(target.noise_density > 0)) continue;
      for (std::size_t c = 0; c < n_static; ++c) {
        move_rows[t].push_back(MoveRows(states[t], options, at, candidates[c]));
      }
    }
    auto windows = [&](std::size_t t, std::size_t c, TimeWindow* move, TimeWindow* capture) {
      const double t0 = states[t].t_now_s;
      *move = TimeWindow{t0, t0 + timing[c].lead_s};
      *capture = TimeWindow{t0 + timing[c].lead_s, t0 + timing[c].lead_s + timing[c].capture_s};
    };
    std::vector<CandidateScore> scores(candidates.size());
    for (std::size_t c = 0; c < candidates.size(); ++c) {
      CandidateScore& sc = scores[c];
      sc.pose = candidates[c];
      sc.seconds = timing[c].total_s;
      for (std::size_t t = 0; t < states.size(); ++t) {
        TimeWindow wm, wc;
        windows(t, c, &wm, &wc);
        Eigen::MatrixXd rows = states[t].Rows(states[t].cand[c], wc);
        if (c < move_rows[t].size() && move_rows[t][c].J.rows() > 0) {
          rows = Stack(states[t].Rows(move_rows[t][c], wm), rows);
          sc.move = true;
        }
        const double g = LogDetGain(rows, factors[t]);
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
    for (std::size_t t = 0; t < states.size(); ++t) {
      TargetState& s = states[t];
      TimeWindow wm, wc;
      windows(t, best, &wm, &wc);
      if (best < move_rows[t].size() && s.Append(move_rows[t][best], wm)) {
        ++s.moves;
        if (step > 0 || advice.poses_to_gate != 0) ++advice.models[t].planned_moves;
      }
      if (s.Append(s.cand[best], wc)) {
        ++(candidates[best].is_rate() ? s.rate_segments : s.poses);
        if (step > 0 || advice.poses_to_gate != 0) {
          ++(candidates[best].is_rate() ? advice.models[t].planned_rate_segments
                                        : advice.models[t].planned_poses);
        }
      }
      s.t_now_s += timing[best].total_s;
    }
    no_move = candidates[best].is_rate();
    at = no_move ? AfterRateSegment(at, candidates[best]) : candidates[best];
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
  if (!advice.continuation.empty()) {
    for (std::size_t t = 0; t < states.size(); ++t)
      advice.models[t].sigma_planned = states[t].Sigma();
  }
  advice.ok = true;
  return advice;
}

}  // namespace turncal
