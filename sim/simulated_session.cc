#include "sim/simulated_session.h"

namespace turncal {

SessionOutcome RunSimulatedSession(const MeasurementModel& model, const Eigen::VectorXd& truth,
                                   const SensorClass& sensor, const CalibratorOptions& options,
                                   const GateOptions& gate, double dwell_s, int max_poses,
                                   const PoseChooser& choose, std::mt19937_64* rng) {
  SessionOutcome out;
  Calibrator calibrator(options);
  std::optional<Estimate> estimate;
  for (int i = 0; i < max_poses; ++i) {
    const std::optional<TablePose> pose =
        choose(i, calibrator, estimate && estimate->ok ? &*estimate : nullptr);
    if (!pose) break;
    out.poses.push_back(*pose);
    const PoseRecord record = SimulateRecord(model, truth, *pose, sensor, dwell_s, rng);
    if (!calibrator.add_pose(record, nullptr)) continue;
    estimate = calibrator.solve();
    if (!estimate->ok) continue;
    const DataReport data =
        AnalyzeData(model, estimate->theta, calibrator.weighted_poses(), ObservabilityOptions{});
    out.last_gate = EvaluateGate(model, *estimate, data, gate);
    out.last_estimate = *estimate;
    if (out.last_gate.pass) {
      out.poses_to_gate = i + 1;
      break;
    }
  }
  return out;
}

PoseChooser FixedSequence(std::vector<TablePose> design) {
  return [design = std::move(design)](int index, const Calibrator&,
                                      const Estimate*) -> std::optional<TablePose> {
    if (index >= static_cast<int>(design.size())) return std::nullopt;
    return design[static_cast<std::size_t>(index)];
  };
}

PoseChooser PlannedSequence(const MeasurementModel& model, const GateOptions& gate, double dwell_s,
                            PlannerOptions planner) {
  planner.horizon = 1;  // only the recommendation is needed
  planner.dwell_s = dwell_s;
  return [&model, gate, dwell_s, planner](int, const Calibrator& calibrator,
                                          const Estimate* estimate) -> std::optional<TablePose> {
    const PlanningTarget target = TargetFromCalibrator(
        calibrator, estimate ? estimate->theta : model.nominal(), dwell_s, gate);
    const NextPoseAdvice advice = PlanNextPose({target}, planner);
    if (!advice.ok) return std::nullopt;
    return advice.pose;
  };
}

}  // namespace turncal
