#pragma once
// Next-pose planning: from a grid of reachable table poses, the one that most increases the log
// determinant of the Fisher information (D-optimal design) summed over the models in use, the
// sigma each parameter is expected to have after it, and how many more poses the gate needs
// (greedy continuation until the predicted precision passes).
//
// The information is that of the linearised model at a fixed parameter point (the current
// estimate, or nominal values before there is one), in scaled units (ParameterScale), plus a weak
// prior of `prior_sigma_scaled` on every scaled parameter so that log det is finite before the
// data determine everything (Bayesian D-optimality). Its value is irrelevant once the data
// dominate; with the default 1 it is a prior of 100 % on scale factors, 1 rad on angles and the
// excitation's full magnitude on biases, far above any tolerance.

#include <string>
#include <vector>

#include "core/observability.h"
#include "core/publish_gate.h"

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
  // What a new pose will weigh: ExpectedSqrtInformation(noise_density, pose_offset, dwell).
  Eigen::Matrix3d sqrt_information = Eigen::Matrix3d::Identity();
  std::vector<WeightedPose> captured;  // poses already in the calibrator
  GateOptions gate;
};

struct PlannerOptions {
  PoseGrid grid;
  double prior_sigma_scaled = 1.0;
  int horizon = 60;  // the most poses the greedy continuation looks ahead
  int top = 5;       // candidates listed in the advice

  bool IsValid(std::string* error) const;
};

struct CandidateScore {
  TablePose pose;
  double gain = 0.0;                // increase of sum_models log det F
  std::vector<double> model_gains;  // per target
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
  std::vector<CandidateScore> top;  // best first
  std::vector<ModelOutlook> models;
  // Poses still needed for the predicted gate, counting the recommended one; 0 when the captured
  // poses already meet it; -1 when the horizon is not enough (the continuation then holds the
  // `horizon` poses tried) or a gauge blocks the gate (the continuation is then empty).
  int poses_to_gate = -1;
  std::vector<TablePose> continuation;  // the greedy plan those poses form, recommended first
};

NextPoseAdvice PlanNextPose(const std::vector<PlanningTarget>& targets,
                            const PlannerOptions& options);

}  // namespace turncal
