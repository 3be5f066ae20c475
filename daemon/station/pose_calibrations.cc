#include "daemon/station/pose_calibrations.h"

#include <mutex>

#include "daemon/station/device_pipeline.h"
#include "daemon/station/station.h"
#include "daemon/station/thermal_pipeline.h"
#include "protocol/observability_json.h"

namespace turncal::daemon {

PoseCalibrations::PoseCalibrations(const std::vector<std::string>& models,
                                   const StationOptions& options, const SensorClass& sensor) {
  models_.reserve(models.size());
  for (const auto& name : models) models_.push_back(MakePoseModel(name, options, sensor));
}

std::vector<std::string> PoseCalibrations::StoredNames() const {
  std::vector<std::string> names;
  for (const auto& m : models_) names.push_back(m->name());
  return names;
}

bool PoseCalibrations::NeedsMoves() const {
  for (const auto& m : models_) {
    if (m->model && m->model->sensor() == SensorKind::kGyroscope) return true;
  }
  return false;
}

void PoseCalibrations::OnRecord(DevicePipeline& d, const PoseRecord& record, double t_s,
                                bool resuming, CalibrationHost& host) {
  for (auto& owned : models_) {
    ModelPipeline& m = *owned;
    if (!m.TriadOf(record)) continue;  // e.g. a rate segment holds the gyro only
    auto job = std::make_shared<ModelUpdate>();
    job->device_poses = d.records_used.size();
    // The calibrator is only touched under its lock (the worker solves; NextPose reads).
    auto work = [&m, record, job, gate = d.gate] { m.AddAndSolve(record, gate, job.get()); };
    // The station may be replaced (reset, reload) before `done` runs: the host guards it.
    host.Defer(std::move(work), [this, &d, &m, t_s, job, resuming, &host] {
      Apply(d, m, t_s, *job, resuming, host);
    });
  }
}

void PoseCalibrations::Apply(DevicePipeline& d, ModelPipeline& m, double t_s,
                             const ModelUpdate& job, bool resuming, CalibrationHost& host) {
  if (!job.added) {
    host.Publish({{"class", "ERROR"},
                  {"device", d.name},
                  {"model", m.name()},
                  {"message", "pose not used: " + job.error}});
    return;
  }
  m.TakeUpdate(job);
  if (!job.solved) return;
  // The drift a calibrator identified goes to the device's noise profile: the sequencer's
  // stillness tests allow for it, and noise/DEVICE.json keeps it (rewritten when the scale moves
  // by more than 1 %, or the triad had none).
  if (m.estimate.ok && m.calibrator->options().identify_drift && d.RecordIdentifiedDrift(m)) {
    host.SaveNoiseProfile(d);
  }
  if (!resuming) {
    // Every gated parameter's sigma against its tolerance (the watch view's bars).
    nlohmann::json event = {
        {"class", "ESTIMATE"}, {"t", t_s}, {"device", d.name}, {"model", m.name()}};
    event.update(m.EstimateEventJson(d.gate));
    event["gate"] = ToJson(m.gate);
    host.Publish(event);
  }
  if (m.gate.pass && !resuming) {
    host.Activate(d, m, t_s, nullptr);
  } else if (m.gate.pass) {
    m.ApplyCurrentEstimate();
  }
}

void PoseCalibrations::OnFinish(DevicePipeline& d, CalibrationHost& host) {
  SolvePending(d, host, /*resuming=*/false);
}

void PoseCalibrations::OnResumed(DevicePipeline& d, CalibrationHost& host) {
  SolvePending(d, host, /*resuming=*/true);
  // A calibration whose gate passed on the journal's poses but that was never activated (held
  // while the unit did not sit as its mount said, issue 38; or a crash before its document was
  // written) is activated now: the station (CalibrationHost::Activate) holds it again if the
  // unit still does not sit as configured.
  const double t_s = d.records_used.empty() ? 0.0 : d.records_used.back().t_end_s;
  for (auto& owned : models_) {
    ModelPipeline& m = *owned;
    std::string error;
    if (m.gate.pass && m.active_version() == 0 && m.HasEstimate(&error)) {
      host.Activate(d, m, t_s, nullptr);
    }
  }
}

void PoseCalibrations::OnIdle(DevicePipeline& d, CalibrationHost& host) {
  if (d.records_used.size() == idle_solved_at_) return;
  idle_solved_at_ = d.records_used.size();
  SolvePending(d, host, /*resuming=*/false);
}

void PoseCalibrations::SolvePending(DevicePipeline& d, CalibrationHost& host, bool resuming) {
  for (auto& owned : models_) {
    ModelPipeline& m = *owned;
    if (!m.HasPending()) continue;
    auto job = std::make_shared<ModelUpdate>();
    job->device_poses = d.records_used.size();
    job->added = true;
    auto work = [&m, job, gate = d.gate] { m.SolvePending(gate, job.get()); };
    host.Defer(std::move(work), [this, &d, &m, job, resuming, &host] {
      const double t_s = d.records_used.empty() ? 0.0 : d.records_used.back().t_end_s;
      Apply(d, m, t_s, *job, resuming, host);
    });
  }
}

std::vector<PlanningTarget> PoseCalibrations::PlanningTargets(const DevicePipeline& d,
                                                              double dwell_s) const {
  std::vector<PlanningTarget> targets;
  for (const auto& owned : models_) {
    const ModelPipeline& m = *owned;
    // The drift model and the poses' times: a new pose is weighed by what it adds given every
    // earlier one at the time the table would reach it (core/planning/pose_planner.h).
    // A new pose's white noise from the device's own noise profile when it has one.
    // A gyroscope's also from rate segments (the table's rates, [table] plan_rates_dps) and the
    // moves between static poses (core/planning/gyro_planning.h).
    const NoiseProfile* noise = d.sequencer->noise();
    const int triad = m.triad();
    std::lock_guard lock(*m.calibrator_mutex);  // a solve in progress finishes first
    targets.push_back(TargetFromCalibrator(
        *m.calibrator, m.estimate.ok ? m.estimate.theta : m.model->nominal(), dwell_s, d.gate,
        noise ? noise->sigma[static_cast<std::size_t>(triad)] : std::nullopt,
        noise ? noise->rate_hz : 0.0));
  }
  return targets;
}

nlohmann::json PoseCalibrations::NextPose(const DevicePipeline& d,
                                          const StationOptions& options) const {
  return ToJson(
      PlanNextPose(PlanningTargets(d, options.sequencer.dwell_s), PlannerFor(d, options)));
}

PlannerOptions PoseCalibrations::PlannerFor(const DevicePipeline& d,
                                            const StationOptions& options) {
  PlannerOptions planner;
  planner.motion = options.table;
  planner.objective = options.plan_objective;
  planner.dwell_s = options.sequencer.dwell_s;
  planner.rates = options.plan_rates;
  planner.moves = options.sequencer.moves.enabled;
  // From where the table was last announced; the move into the next pose counts when the
  // sequencer tracks one (a static pose captured there, no rate segment since).
  if (const auto at = d.sequencer->announced()) planner.table_at = *at;
  planner.move_from_table_at = d.sequencer->moves().tracking();
  planner.move_rest_s = d.MoveRestSeconds(options.table, planner.move_rest_s);
  return planner;
}

}  // namespace turncal::daemon
