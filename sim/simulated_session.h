#pragma once
// A whole calibration session in memory, pose by pose, as the daemon will run it: simulate the
// pose's record, add it, solve, analyse, gate; stop at the first pose where the gate passes.
// Compares pose sequences (a fixed design against next-pose planning) with the real calibrator
// and gate rather than with predictions.

#include <functional>
#include <optional>
#include <random>
#include <vector>

#include "core/analysis/publish_gate.h"
#include "core/estimation/calibrator.h"
#include "core/planning/pose_planner.h"
#include "sim/synthetic.h"

namespace turncal {

struct SessionOutcome {
  int poses_to_gate = -1;  // poses when the gate first passed; -1 when it never did
  std::vector<TablePose> poses;
  Estimate last_estimate;
  GateResult last_gate;
};

// Chooses pose `index` (0-based) given the calibrator so far and its last estimate (null before
// the first solve); nullopt ends the session.
using PoseChooser =
    std::function<std::optional<TablePose>(int index, const Calibrator&, const Estimate*)>;

SessionOutcome RunSimulatedSession(const MeasurementModel& model, const Eigen::VectorXd& truth,
                                   const SensorClass& sensor, const CalibratorOptions& options,
                                   const GateOptions& gate, double dwell_s, int max_poses,
                                   const PoseChooser& choose, std::mt19937_64* rng);

// The poses of `design` in order, then nothing.
PoseChooser FixedSequence(std::vector<TablePose> design);

// Next-pose planning from the current estimate (nominal values until the first solve succeeds).
PoseChooser PlannedSequence(const MeasurementModel& model, const GateOptions& gate, double dwell_s,
                            PlannerOptions planner);

}  // namespace turncal
