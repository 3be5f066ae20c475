#include "core/planning/pose_planner.h"

#include <fmt/format.h>

#include <Eigen/Cholesky>
#include <algorithm>
#include <cmath>

#include "core/frames/units.h"
#include "core/planning/target_state.h"

namespace turncal {

namespace {

using planning::CandidateRows;
using planning::LogDetGain;
using planning::MoveRows;
using planning::PlannedRows;
using planning::Stack;
using planning::TargetState;
using planning::WhiteVariance;

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

namespace {

// A candidate's timing from where the table is: the seconds before its capture, the capture's
// and the whole (a rate segment's spin-down included).
struct Timing {
  double lead_s = 0.0, capture_s = 0.0, total_s = 0.0;
};

// PlanNextPose's greedy search, in steps: the candidates, each target's state, where the table
// is, then per step the candidates' timing, the moves into them, their scores and the best one
// taken, until the gate passes or the horizon ends.
class NextPosePlanner {
 public:
  NextPosePlanner(const std::vector<PlanningTarget>& targets, const PlannerOptions& options)
      : targets_(targets), options_(options) {}

  NextPoseAdvice Run() {
    if (!options_.IsValid(&advice_.error)) return advice_;
    if (targets_.empty()) {
      advice_.error = "no model to plan for";
      return advice_;
    }
    if (!ListCandidates()) return advice_;
    states_.resize(targets_.size());
    for (std::size_t t = 0; t < targets_.size(); ++t) {
      if (!StartTarget(t)) return advice_;
    }
    PlaceTable();
    StartOutlook();
    timing_.resize(candidates_.size());
    move_rows_.resize(states_.size());
    for (int step = 0; step < options_.horizon; ++step) {
      if (!Step(step)) break;
    }
    if (advice_.poses_to_gate == 0) advice_.seconds_to_gate = 0.0;
    if (!advice_.continuation.empty()) {
      for (std::size_t t = 0; t < states_.size(); ++t)
        advice_.models[t].sigma_planned = states_[t].Sigma();
    }
    advice_.ok = true;
    return advice_;
  }

 private:
  // The grid's static poses, then (with a gyroscope and rates) the rate segments.
  bool ListCandidates() {
    candidates_ = options_.grid.Candidates();
    n_static_ = candidates_.size();
    const bool any_gyro =
        std::any_of(targets_.begin(), targets_.end(), [](const PlanningTarget& t) {
          return t.model && t.model->sensor() == SensorKind::kGyroscope;
        });
    if (any_gyro && !options_.rates.rates_dps.empty()) {
      const std::vector<double> held[3] = {AxisValues(options_.grid.phi),
                                           AxisValues(options_.grid.gamma),
                                           AxisValues(options_.grid.psi)};
      const std::vector<TablePose> rates = RateCandidates(options_.rates, options_.motion, held);
      if (candidates_.size() + rates.size() > static_cast<std::size_t>(kMaxCandidates)) {
        advice_.error = fmt::format("{} static poses and {} rate segments; at most {} candidates",
                                    candidates_.size(), rates.size(), kMaxCandidates);
        return false;
      }
      candidates_.insert(candidates_.end(), rates.begin(), rates.end());
    }
    advice_.candidates = static_cast<int>(candidates_.size());
    advice_.objective = options_.objective;
    return true;
  }

  // Target t's state: its information from what it captured (with drift: the records in time
  // order), every candidate's rows, whether a gauge blocks its gate.
  bool StartTarget(std::size_t t) {
    const PlanningTarget& target = targets_[t];
    const bool drift = target.drift.enabled();
    if (target.model == nullptr || target.theta.size() != target.model->num_parameters() ||
        !target.theta.allFinite() || !target.sqrt_information.allFinite() ||
        !std::isfinite(target.noise_density) || !std::isfinite(target.pose_offset_sigma) ||
        !std::isfinite(target.rate_accuracy) ||
        (drift && target.captured_windows.size() != target.captured.size())) {
      advice_.error = fmt::format("planning target {} is incomplete", t);
      return false;
    }
    if (!target.gate.IsValid(&advice_.error)) return false;
    if (drift && !target.drift.IsValid(&advice_.error)) return false;
    const MeasurementModel& model = *target.model;
    TargetState& s = states_[t];
    s.target = &target;
    s.gyro = model.sensor() == SensorKind::kGyroscope;
    s.scales = ParameterScales(model);
    const int N = model.num_parameters();
    s.prior = Eigen::MatrixXd::Identity(N, N) /
              (options_.prior_sigma_scaled * options_.prior_sigma_scaled);
    s.records = static_cast<int>(target.captured.size());
    for (const auto& p : target.captured) {
      ++(p.raw_residual ? s.moves : p.pose.is_rate() ? s.rate_segments : s.poses);
    }
    if (drift) {
      advice_.drift_aware = true;
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
    s.cand.reserve(candidates_.size());
    for (const auto& c : candidates_) s.cand.push_back(CandidateRows(s, c, options_.dwell_s));
    const Eigen::MatrixXd gauge = GaugeDirections(model, target.theta);
    if (gauge.cols() > 0 && !target.gate.accept_gauge_dependent_correction) {
      for (int j : GatedParameters(model)) {
        if (gauge.row(j).cwiseAbs().maxCoeff() > 1e-12) s.gauge_blocks = true;
      }
    }
    return true;
  }

  // Where the table is: as told, else the first target's latest captured pose. After a rate
  // segment it stands at the segment's attitude and no move into the next pose is credited.
  void PlaceTable() {
    if (options_.table_at) {
      at_ = *options_.table_at;
    } else if (const PlanningTarget& first = targets_.front(); !first.captured.empty()) {
      at_ = first.captured.back().pose;
      if (first.captured_windows.size() == first.captured.size()) {
        at_ =
            first.captured[static_cast<std::size_t>(TimeOrder(first.captured_windows).back())].pose;
      }
    }
    // No move into the next pose: the table is in a rate segment, or nothing was captured yet.
    no_move_ = options_.move_from_table_at ? !*options_.move_from_table_at
                                           : at_.is_rate() || targets_.front().captured.empty();
    if (at_.is_rate()) at_ = AfterRateSegment(at_, at_);
  }

  // Each model's sigma now and what it captured; whether the gate passes already or a gauge
  // blocks it.
  void StartOutlook() {
    for (const auto& s : states_) {
      ModelOutlook o;
      o.model = s.target->model->name();
      for (const auto& p : s.target->model->parameters()) o.names.push_back(p.name);
      o.sigma_now = s.Sigma();
      o.gauge_blocks = s.gauge_blocks;
      o.captured_poses = s.poses;
      o.captured_rate_segments = s.rate_segments;
      o.captured_moves = s.moves;
      advice_.models.push_back(o);
    }
    if (AllPass()) advice_.poses_to_gate = 0;
    blocked_ = std::any_of(states_.begin(), states_.end(),
                           [](const TargetState& s) { return s.gauge_blocks; });
  }

  bool AllPass() const {
    bool pass = true;
    std::vector<std::string> shortfalls;
    for (const auto& s : states_) pass = s.Passes(s.Sigma(), &shortfalls) && pass;
    return pass;
  }

  // One greedy step: the best candidate from where the table is, taken. False: stop planning.
  bool Step(int step) {
    TimeCandidates();
    PlanMoves();
    const std::vector<CandidateScore> scores = ScoreCandidates();
    std::size_t best = 0;
    for (std::size_t c = 1; c < scores.size(); ++c)
      if (scores[c].score > scores[best].score) best = c;
    if (step == 0) Recommend(scores, best);
    Take(step, best);
    if (step == 0) {
      for (std::size_t t = 0; t < states_.size(); ++t) {
        advice_.models[t].sigma_after = states_[t].Sigma();
        states_[t].Passes(advice_.models[t].sigma_after, &advice_.models[t].shortfalls_after);
      }
    }
    // Already passing, or never passing (a gauge blocks the gate): only the recommendation.
    if (advice_.poses_to_gate == 0 || blocked_) return false;
    advice_.continuation.push_back(candidates_[best]);
    advice_.continuation_seconds.push_back(scores[best].seconds);
    planned_s_ += scores[best].seconds;
    if (advice_.poses_to_gate < 0 && AllPass()) {
      advice_.poses_to_gate = step + 1;
      advice_.seconds_to_gate = planned_s_;
    }
    return !(advice_.poses_to_gate > 0 && step + 1 >= options_.min_continuation);
  }

  void TimeCandidates() {
    for (std::size_t c = 0; c < candidates_.size(); ++c) {
      Timing& tm = timing_[c];
      if (candidates_[c].is_rate()) {
        tm.total_s = RateSegmentSeconds(options_.motion, options_.rates, at_, candidates_[c],
                                        options_.dwell_s, &tm.lead_s);
        tm.capture_s = RateCaptureSeconds(candidates_[c].rate_radps, options_.dwell_s);
      } else {
        tm.lead_s = options_.motion.MoveSeconds(at_, candidates_[c]) + options_.motion.settle_s;
        tm.capture_s = options_.dwell_s;
        tm.total_s = tm.lead_s + tm.capture_s;
      }
    }
  }

  // The moves into each static candidate, for the gyroscopes that credit them.
  void PlanMoves() {
    for (std::size_t t = 0; t < states_.size(); ++t) {
      move_rows_[t].clear();
      const PlanningTarget& target = *states_[t].target;
      if (!options_.moves || no_move_ || !states_[t].gyro || !(target.noise_density > 0)) continue;
      for (std::size_t c = 0; c < n_static_; ++c) {
        move_rows_[t].push_back(MoveRows(states_[t], options_, at_, candidates_[c]));
      }
    }
  }

  // Candidate c's move and capture windows on target t's clock.
  void Windows(std::size_t t, std::size_t c, TimeWindow* move, TimeWindow* capture) const {
    const double t0 = states_[t].t_now_s;
    *move = TimeWindow{t0, t0 + timing_[c].lead_s};
    *capture = TimeWindow{t0 + timing_[c].lead_s, t0 + timing_[c].lead_s + timing_[c].capture_s};
  }

  // Each candidate's gain in log det F per model (with the move into it), and its score.
  std::vector<CandidateScore> ScoreCandidates() const {
    std::vector<Eigen::LDLT<Eigen::MatrixXd>> factors;
    for (const auto& s : states_) factors.emplace_back(s.information);
    std::vector<CandidateScore> scores(candidates_.size());
    for (std::size_t c = 0; c < candidates_.size(); ++c) {
      CandidateScore& sc = scores[c];
      sc.pose = candidates_[c];
      sc.seconds = timing_[c].total_s;
      for (std::size_t t = 0; t < states_.size(); ++t) {
        TimeWindow wm, wc;
        Windows(t, c, &wm, &wc);
        Eigen::MatrixXd rows = states_[t].Rows(states_[t].cand[c], wc);
        if (c < move_rows_[t].size() && move_rows_[t][c].J.rows() > 0) {
          rows = Stack(states_[t].Rows(move_rows_[t][c], wm), rows);
          sc.move = true;
        }
        const double g = LogDetGain(rows, factors[t]);
        sc.model_gains.push_back(g);
        sc.gain += g;
      }
      sc.score = options_.objective == PlanObjective::kTime ? sc.gain / sc.seconds : sc.gain;
    }
    return scores;
  }

  // The first step's recommendation: the best candidate and the top ones by score.
  void Recommend(const std::vector<CandidateScore>& scores, std::size_t best) {
    std::vector<std::size_t> order(scores.size());
    for (std::size_t i = 0; i < order.size(); ++i) order[i] = i;
    const auto k = std::min<std::size_t>(static_cast<std::size_t>(options_.top), order.size());
    std::partial_sort(order.begin(), order.begin() + static_cast<std::ptrdiff_t>(k), order.end(),
                      [&](std::size_t a, std::size_t b) {
                        return scores[a].score > scores[b].score ||
                               (scores[a].score == scores[b].score && a < b);
                      });
    for (std::size_t i = 0; i < k; ++i) advice_.top.push_back(scores[order[i]]);
    advice_.pose = candidates_[best];
    advice_.gain = scores[best].gain;
    advice_.seconds = scores[best].seconds;
  }

  // Every target takes candidate `best` (and the move into it); the table goes there.
  void Take(int step, std::size_t best) {
    for (std::size_t t = 0; t < states_.size(); ++t) {
      TargetState& s = states_[t];
      TimeWindow wm, wc;
      Windows(t, best, &wm, &wc);
      if (best < move_rows_[t].size() && s.Append(move_rows_[t][best], wm)) {
        ++s.moves;
        if (step > 0 || advice_.poses_to_gate != 0) ++advice_.models[t].planned_moves;
      }
      if (s.Append(s.cand[best], wc)) {
        ++(candidates_[best].is_rate() ? s.rate_segments : s.poses);
        if (step > 0 || advice_.poses_to_gate != 0) {
          ++(candidates_[best].is_rate() ? advice_.models[t].planned_rate_segments
                                         : advice_.models[t].planned_poses);
        }
      }
      s.t_now_s += timing_[best].total_s;
    }
    no_move_ = candidates_[best].is_rate();
    at_ = no_move_ ? AfterRateSegment(at_, candidates_[best]) : candidates_[best];
  }

  const std::vector<PlanningTarget>& targets_;
  const PlannerOptions& options_;
  NextPoseAdvice advice_;
  std::vector<TablePose> candidates_;
  std::size_t n_static_ = 0;
  std::vector<TargetState> states_;
  TablePose at_;
  bool no_move_ = false;
  bool blocked_ = false;
  std::vector<Timing> timing_;
  std::vector<std::vector<PlannedRows>> move_rows_;
  double planned_s_ = 0.0;
};

}  // namespace

NextPoseAdvice PlanNextPose(const std::vector<PlanningTarget>& targets,
                            const PlannerOptions& options) {
  return NextPosePlanner(targets, options).Run();
}

}  // namespace turncal
