#pragma once
// Next-pose planning: from a grid of reachable table poses, the one that most increases the log
// determinant of the Fisher information (D-optimal design) summed over the models in use per
// second of table time (the move at the table's rates, settling and the dwell; or per pose), the
// sigma each parameter is expected to have after it, and how many more poses and seconds the
// gate needs (greedy continuation until the predicted precision passes).
//
// With a drift model (core/estimation/bias_drift.h) a pose's information depends on when it is
// taken: its error shares the bias wander with the poses near it in time, so the planner scores
// each candidate by its innovation given every earlier pose at the time the table would reach it
// (core/planning/drift_design.h). Orders in which slow drift would look like a sensor parameter
// then score low by themselves (docs/OBSERVABILITY.md "Planning for time").
//
// The information is that of the linearised model at a fixed parameter point (the current
// estimate, or nominal values before there is one), in scaled units (ParameterScale), plus a weak
// prior of `prior_sigma_scaled` on every scaled parameter so that log det is finite before the
// data determine everything (Bayesian D-optimality). Its value is irrelevant once the data
// dominate; with the default 1 it is a prior of 100 % on scale factors, 1 rad on angles and the
// excitation's full magnitude on biases, far above any tolerance.

#include <optional>
#include <string>
#include <vector>

#include "core/analysis/observability.h"
#include "core/analysis/publish_gate.h"
#include "core/estimation/bias_drift.h"
#include "core/estimation/calibrator.h"
#include "core/planning/table_motion.h"

namespace turncal {

// One table axis's reachable values: min, min + step, ... up to max (inclusive), degrees.
struct AxisRange {
  double min_deg = 0.0;
  double max_deg = 0.0;
  double step_deg = 0.0;  // 0: only min_deg
};

// Each candidate costs a 3 x N Jacobian per model and one solve per planning step.
inline constexpr int kMaxCandidates = 100000;

struct PoseGrid {
  AxisRange phi{-180.0, 150.0, 30.0};  // inner axis
  AxisRange gamma{-90.0, 90.0, 30.0};  // middle axis
  AxisRange psi{-180.0, 135.0, 45.0};  // outer axis

  bool IsValid(std::string* error) const;
  std::vector<TablePose> Candidates() const;
};

// One model in use, as the planner sees it.
struct PlanningTarget {
  const MeasurementModel* model = nullptr;  // not owned
  Eigen::VectorXd theta;                    // linearisation point
  // What a new pose will weigh: ExpectedSqrtInformation(noise_density, pose_offset, dwell), the
  // white noise over its dwell (and any independent per-pose offset) without the drift.
  Eigen::Matrix3d sqrt_information = Eigen::Matrix3d::Identity();
  // Poses already in the calibrator. Without drift: as the calibrator weighs them. With drift:
  // weighed by their own white noise only (Calibrator::PlanningPoses), with their windows on the
  // sensor's clock in `captured_windows` (same order, any time order).
  std::vector<WeightedPose> captured;
  std::vector<TimeWindow> captured_windows;
  BiasDrift drift;  // not enabled: poses independent, time only costs
  GateOptions gate;
};

enum class PlanObjective {
  kTime,   // the most information per second of table time (move, settle, dwell)
  kPoses,  // the most information per pose (the planner before issue 19)
};
const char* ToString(PlanObjective objective);

struct PlannerOptions {
  PoseGrid grid;
  TableMotion motion;
  double dwell_s = 5.0;  // a planned pose's dwell, seconds
  PlanObjective objective = PlanObjective::kTime;
  // Where the table is now; unset: the latest captured pose of the first target (home, all
  // angles 0, when nothing is captured).
  std::optional<TablePose> table_at;
  double prior_sigma_scaled = 1.0;
  int horizon = 60;  // the most poses the greedy continuation looks ahead
  // The continuation goes on past the predicted gate to at least this many poses (a whole
  // session's plan rather than the shortest one; horizon still bounds it).
  int min_continuation = 0;
  int top = 5;  // candidates listed in the advice

  bool IsValid(std::string* error) const;
};

struct CandidateScore {
  TablePose pose;
  double gain = 0.0;                // increase of sum_models log det F
  std::vector<double> model_gains;  // per target
  double seconds = 0.0;             // move + settle + dwell from where the table is
  double score = 0.0;               // gain per second (kTime) or gain (kPoses)
};

struct ModelOutlook {
  std::string model;
  std::vector<std::string> names;
  Eigen::VectorXd sigma_now;                  // predicted from the captured poses (and the prior)
  Eigen::VectorXd sigma_after;                // after the recommended pose
  std::vector<std::string> shortfalls_after;  // gated parameters still above tolerance
  bool gauge_blocks = false;  // the correction rests on a gauge the gate does not accept
};

struct NextPoseAdvice {
  bool ok = false;
  std::string error;
  int candidates = 0;
  TablePose pose;  // the recommendation
  double gain = 0.0;
  double seconds = 0.0;  // the recommendation's move + settle + dwell
  PlanObjective objective = PlanObjective::kTime;
  bool drift_aware = false;         // some target had a drift model
  std::vector<CandidateScore> top;  // best first
  std::vector<ModelOutlook> models;
  // Poses still needed for the predicted gate, counting the recommended one; 0 when the captured
  // poses already meet it; -1 when the horizon is not enough (the continuation then holds the
  // `horizon` poses tried) or a gauge blocks the gate (the continuation is then empty).
  int poses_to_gate = -1;
  double seconds_to_gate = -1.0;  // their table time (moves, settling, dwells); same conventions
  std::vector<TablePose> continuation;       // the greedy plan those poses form, recommended first
  std::vector<double> continuation_seconds;  // each one's move + settle + dwell
};

// A planning target for the model a calibrator estimates, at `theta`, from its poses so far and
// its noise and drift model, with a new pose's dwell of `dwell_s`. A new pose's white noise is
// the larger of the calibrator's density floor and, when given, the device's measured per-sample
// sigma of the model's triad at `rate_hz` (the noise profile); with neither (a magnetometer
// before start-up), the captured poses' own white noise scaled to the dwell, else the drift's
// sigma (errs towards less information per pose).
PlanningTarget TargetFromCalibrator(const Calibrator& calibrator, const Eigen::VectorXd& theta,
                                    double dwell_s, const GateOptions& gate,
                                    const std::optional<Eigen::Vector3d>& sample_sigma = {},
                                    double rate_hz = 0.0);

NextPoseAdvice PlanNextPose(const std::vector<PlanningTarget>& targets,
                            const PlannerOptions& options);

}  // namespace turncal
