#pragma once
// A fixture's session in memory (issue 38): several units, each in its own mount with its own
// truth, see every pose the table takes; each has its own calibrator and gate. The poses come
// from a fixed design (the cube) or from the batch's next-pose planning (every unit still short
// of its gate planned together, core/planning/pose_planner.h); the session ends when the last
// unit's gate passes. What `turncal plan-vs-cube --units N` measures: poses and table seconds to
// the last gate, units per hour. Independent pose noise, as sim/simulated_session.h (drift and
// bytes: the pipeline Monte Carlo).

#include <random>
#include <vector>

#include "core/analysis/publish_gate.h"
#include "core/estimation/calibrator.h"
#include "core/planning/pose_planner.h"
#include "sim/synthetic.h"

namespace turncal {

struct BatchUnit {
  const MeasurementModel* model = nullptr;  // in the unit's mount's context; not owned
  Eigen::VectorXd truth;
  CalibratorOptions options;
};

struct BatchOutcome {
  int poses_to_last_gate = -1;          // -1: some unit never passed
  std::vector<int> unit_poses_to_gate;  // per unit; -1: never
  std::vector<TablePose> poses;         // the poses taken
};

// `design`: the poses in order (empty: planned with `planner`, from where the table is).
BatchOutcome RunSimulatedBatch(const std::vector<BatchUnit>& units, const SensorClass& sensor,
                               const GateOptions& gate, double dwell_s, int max_poses,
                               const std::vector<TablePose>& design, PlannerOptions planner,
                               std::mt19937_64* rng);

}  // namespace turncal
