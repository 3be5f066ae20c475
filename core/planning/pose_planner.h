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
// A gyroscope model (issue 21) also learns from rate segments, which are candidates of their own
// when the table can hold rates (PlannerOptions::rates), and from the move into each static pose,
// which the planner credits it with as the calibrator would weigh it (core/planning/
// gyro_planning.h; docs/OBSERVABILITY.md "Planning a gyroscope").
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
#include "core/planning/gyro_planning.h"
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
  // A gyroscope's rate segments and moves (core/planning/gyro_planning.h), weighed as the
  // calibrator weighs them: the white noise density (rad/s/sqrt(Hz); 0: no move is credited), the
  // pose-to-pose offset (rad/s; already in sqrt_information) and the table's relative rate
  // accuracy.
  double noise_density = 0.0;
  double pose_offset_sigma = 0.0;
  double rate_accuracy = 0.0;
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
  // Rate segments to consider besides the grid's static poses (a gyroscope learns from them; the
  // other models gain nothing). No rates: none.
  RatePlan rates;
  // Credit a gyroscope with the move into each static pose (the sequencer integrates the moves
  // between static poses: [sequencer] moves). Not after a rate segment, whose next move the
  // sequencer drops.
  bool moves = true;
  // The rest a move spans besides the table's motion and settling: from the last dwell sample to
  // the table's start, and from the settling's end until the sequencer's stillness detector lets
  // the next dwell begin (its window and look-ahead, the controller's reaction). A longer move
  // gathers more of the gyro's angle random walk for the same turn. The station measures it on
  // the moves it captured.
  double move_rest_s = 1.0;
  // Where the table is now (a rate segment: the table was turning, so no move is credited into
  // the next pose); unset: the latest captured pose of the first target (home, all
  // angles 0, when nothing is captured).
  std::optional<TablePose> table_at;
  // Whether a move into the next pose is being integrated (the sequencer captured a static pose
  // where the table is and tracks the move from it); unset: when some record is captured and the
  // table is not in a rate segment.
  std::optional<bool> move_from_table_at;
  double prior_sigma_scaled = 1.0;
  int horizon = 60;  // the most poses the greedy continuation looks ahead
  // The continuation goes on past the predicted gate to at least this many poses (a whole
  // session's plan rather than the shortest one; horizon still bounds it).
  int min_continuation = 0;
  int top = 5;  // candidates listed in the advice

  bool IsValid(std::string* error) const;
};

struct CandidateScore {
  TablePose pose;                   // a static pose or a rate segment
  double gain = 0.0;                // increase of sum_models log det F
  std::vector<double> model_gains;  // per target
  double seconds = 0.0;  // move + settle + dwell from where the table is (a rate segment: the move
                         // to its attitude, spin-up, steadiness, whole revolutions, spin-down)
  bool move = false;     // a gyroscope is credited with the move into it
  double score = 0.0;    // gain per second (kTime) or gain (kPoses)
};

struct ModelOutlook {
  std::string model;
  std::vector<std::string> names;
  Eigen::VectorXd sigma_now;  // predicted from the captured records (and the prior)
  // The records sigma_now rests on (poses, rate segments, moves), and those the continuation adds
  // (up to the gate, the horizon or min_continuation).
  int captured_poses = 0, captured_rate_segments = 0, captured_moves = 0;
  int planned_poses = 0, planned_rate_segments = 0, planned_moves = 0;
  Eigen::VectorXd sigma_after;    // after the recommended pose
  Eigen::VectorXd sigma_planned;  // after the whole continuation (empty when there is none)
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
