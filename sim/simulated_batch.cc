#include "sim/simulated_batch.h"

#include <memory>
#include <optional>

namespace turncal {

BatchOutcome RunSimulatedBatch(const std::vector<BatchUnit>& units, const SensorClass& sensor,
                               const GateOptions& gate, double dwell_s, int max_poses,
                               const std::vector<TablePose>& design, PlannerOptions planner,
                               std::mt19937_64* rng) {
  BatchOutcome out;
  out.unit_poses_to_gate.assign(units.size(), -1);
  std::vector<std::unique_ptr<Calibrator>> calibrators;
  std::vector<std::optional<Estimate>> estimates(units.size());
  for (const auto& u : units) calibrators.push_back(std::make_unique<Calibrator>(u.options));
  planner.horizon = 1;  // only the recommendation is needed
  planner.dwell_s = dwell_s;
  std::size_t passed = 0;
  for (int i = 0; i < max_poses && passed < units.size(); ++i) {
    TablePose pose;
    if (!design.empty()) {
      if (i >= static_cast<int>(design.size())) break;
      pose = design[static_cast<std::size_t>(i)];
    } else {
      // Every unit still short of its gate, planned together, from where the table is.
      std::vector<PlanningTarget> targets;
      for (std::size_t k = 0; k < units.size(); ++k) {
        if (out.unit_poses_to_gate[k] > 0) continue;
        const auto& e = estimates[k];
        targets.push_back(TargetFromCalibrator(
            *calibrators[k], e && e->ok ? e->theta : units[k].model->nominal(), dwell_s, gate));
      }
      if (!out.poses.empty()) planner.table_at = out.poses.back();
      const NextPoseAdvice advice = PlanNextPose(targets, planner);
      if (!advice.ok) break;
      pose = advice.pose;
    }
    out.poses.push_back(pose);
    for (std::size_t k = 0; k < units.size(); ++k) {
      // Every unit sees the pose (the same draws whether it has passed or not, so that a unit's
      // noise does not depend on the others').
      const PoseRecord record =
          SimulateRecord(*units[k].model, units[k].truth, pose, sensor, dwell_s, rng);
      if (out.unit_poses_to_gate[k] > 0 || !calibrators[k]->add_pose(record, nullptr)) continue;
      estimates[k] = calibrators[k]->solve();
      if (!estimates[k]->ok) continue;
      const DataReport data = AnalyzeData(*units[k].model, estimates[k]->theta,
                                          calibrators[k]->weighted_poses(), ObservabilityOptions{});
      if (EvaluateGate(*units[k].model, *estimates[k], data, gate).pass) {
        out.unit_poses_to_gate[k] = i + 1;
        ++passed;
      }
    }
  }
  if (passed == units.size()) out.poses_to_last_gate = static_cast<int>(out.poses.size());
  return out;
}

}  // namespace turncal
