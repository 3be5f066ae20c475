#include "daemon/station/device_pipeline.h"

#include <algorithm>
#include <cmath>

#include "daemon/station/station.h"
#include "drivers/transport/transport.h"
#include "protocol/calibration_json.h"
#include "protocol/observability_json.h"
#include "protocol/sequencer_json.h"
#include "turncal/version.h"

namespace turncal::daemon {

SequencerOptions DevicePipeline::SequencerOptionsFor(const StationOptions& options,
                                                     const SensorClass& sensor) {
  SequencerOptions so = options.sequencer;
  // A still dwell's halves may differ by the sensor's own bias wander, not only by its white
  // noise: the class's Gauss-Markov drift, scaled by what the calibrator identifies.
  for (int t : {kTriadAcc, kTriadMag}) {
    BiasDrift& wander = so.stillness.bias_drift[static_cast<std::size_t>(t)];
    if (!wander.enabled()) {
      wander = DriftForClass(
          sensor, t == kTriadAcc ? SensorKind::kAccelerometer : SensorKind::kMagnetometer);
    }
  }
  return so;
}

bool DevicePipeline::RecordIdentifiedDrift(const ModelPipeline& m) {
  const int triad = m.triad();
  const NoiseProfile* before = sequencer->noise();
  const auto& stored = before ? before->identified_drift[static_cast<std::size_t>(triad)]
                              : std::optional<IdentifiedDrift>();
  const bool moved =
      !stored || std::abs(std::log(m.estimate.drift_scale_used / stored->scale)) > 0.01;
  sequencer->SetIdentifiedDrift(
      triad, IdentifiedDrift{m.estimate.drift, m.estimate.drift_scale_used, m.estimate.poses});
  return moved;
}

std::vector<PlanningTarget> DevicePipeline::PlanningTargets(double dwell_s) const {
  std::vector<PlanningTarget> targets;
  for (const ModelPipeline& m : models) {
    // The drift model and the poses' times: a new pose is weighed by what it adds given every
    // earlier one at the time the table would reach it (core/planning/pose_planner.h).
    // A new pose's white noise from the device's own noise profile when it has one.
    // A gyroscope's also from rate segments (the table's rates, [table] plan_rates_dps) and the
    // moves between static poses (core/planning/gyro_planning.h).
    const NoiseProfile* noise = sequencer->noise();
    const int triad = m.triad();
    std::lock_guard lock(*m.calibrator_mutex);  // a solve in progress finishes first
    targets.push_back(TargetFromCalibrator(
        *m.calibrator, m.estimate.ok ? m.estimate.theta : m.model->nominal(), dwell_s, gate,
        noise ? noise->sigma[static_cast<std::size_t>(triad)] : std::nullopt,
        noise ? noise->rate_hz : 0.0));
  }
  return targets;
}

double DevicePipeline::MoveRestSeconds(const TableMotion& motion, double fallback) const {
  double sum = 0.0;
  int n = 0;
  for (const PoseRecord& r : records_used) {
    if (!r.move_in) continue;
    const MoveRecord& m = *r.move_in;
    sum += m.duration_s() - motion.MoveSeconds(m.from, m.to) - motion.settle_s;
    ++n;
  }
  return n > 0 ? std::max(0.0, sum / n) : fallback;
}

nlohmann::json DevicePipeline::CalibrationJson(const ModelPipeline& m,
                                               const std::string& sensor_class,
                                               const ModelContext& context) const {
  const DevicePipeline& d = *this;
  const Estimate& e = m.estimate;
  nlohmann::json order = nlohmann::json::array();
  for (const auto& p : e.parameters) order.push_back(p.name);
  nlohmann::json covariance = nlohmann::json::array();
  for (Eigen::Index r = 0; r < e.covariance.rows(); ++r) {
    nlohmann::json row = nlohmann::json::array();
    for (Eigen::Index c = 0; c < e.covariance.cols(); ++c) {
      const double v = e.covariance(r, c);
      row.push_back(std::isfinite(v) ? nlohmann::json(v) : nlohmann::json());
    }
    covariance.push_back(row);
  }
  const std::size_t n = std::min(m.estimate_poses, d.poses_used.size());
  // The poses and records that hold the model's triad (an accelerometer's leave out rate segments).
  nlohmann::json pose_list = nlohmann::json::array();
  for (std::size_t i = 0; i < n; ++i) {
    if (i < d.records_used.size() && !m.TriadOf(d.records_used[i])) continue;
    pose_list.push_back(ToJson(d.poses_used[i]));
  }
  // The records themselves, with the model's triad only, so that the calibration can be
  // re-evaluated (the report's residuals and convergence) without the journal, which `reset`
  // archives.
  nlohmann::json records = nlohmann::json::array();
  for (std::size_t i = 0; i < n && i < d.records_used.size(); ++i) {
    PoseRecord r = d.records_used[i];
    if (!m.TriadOf(r)) continue;
    if (m.triad() != kTriadAcc) r.acc.reset();
    if (m.triad() != kTriadGyr) r.gyr.reset();
    if (m.triad() != kTriadMag) r.mag.reset();
    // A gyroscope's moves go with their blocks (the report re-weighs them): ~80 kB a move of
    // 6 s at 10 ms blocks.
    if (m.triad() != kTriadGyr) r.move_in.reset();
    records.push_back(protocol::ToJson(r));
  }
  nlohmann::json calibrator = protocol::CalibratorJson(m.calibrator->options(), sensor_class);
  if (e.drift.enabled()) {
    // The drift the solve used (the prior times the identified scale): corrected output's sigma
    // grows with it, also after a restart; the configured one stays as the prior.
    calibrator["drift_prior"] = calibrator["drift"];
    calibrator["drift"] = protocol::ToJson(e.drift);
    calibrator["drift_scale"] = DriftScaleJson(e);
  }
  // Device identity and the device-side stored calibration come from the device dialogue of a
  // live station (SetDeviceIdentity); a replay does not have them (null).
  const nlohmann::json provenance = {
      {"poses", pose_list}, {"records", records}, {"device_identity", d.identity}};
  return {{"schema", 1},
          {"class", "CALIBRATION"},
          {"device", d.name},
          {"model", m.model->name()},
          {"version", m.active_version},
          {"software", kVersion},
          {"time", drivers::UtcNowIso8601()},
          {"params", ParamsJson(e)},
          {"parameter_order", order},
          {"covariance", covariance},
          {"gauge", e.gauge},
          {"bias_window", e.bias_window ? protocol::ToJson(*e.bias_window) : nlohmann::json()},
          {"rank", m.rank},
          {"chi2", e.chi2},
          {"dof", e.dof},
          {"p_value", e.p_value},
          {"fit_check", protocol::ToJson(e.fit, m.model->sensor())},
          {"gate", ToJson(m.gate)},
          {"tolerances", protocol::TolerancesJson(*m.model, d.gate)},
          {"context", protocol::ToJson(context)},
          {"calibrator", calibrator},
          {"provenance", provenance}};
}

nlohmann::json DevicePipeline::MovesJson() const {
  const MoveTracker& t = sequencer->moves();
  return {{"enabled", sequencer->options().moves.enabled},
          {"taken", t.moves()},
          {"dropped", t.dropped()},
          {"last_drop", t.last_drop()}};
}

nlohmann::json DevicePipeline::StatusJson() const {
  nlohmann::json model_status = nlohmann::json::object();
  for (const ModelPipeline& m : models) model_status[m.model->name()] = m.StatusJson();
  const SampleCounts& t = sequencer->totals();
  nlohmann::json free_status;
  if (free) {
    free_status = free->StatusJson(records_used.size());
    model_status = free_status["models"];
    free_status.erase("models");
  }
  return {{"poses", poses},
          {"pose_source", free ? "free" : "announced"},
          {"free", free_status},
          {"captured", sequencer->captured()},
          {"rejected", sequencer->rejected()},
          {"busy", sequencer->busy()},
          {"noise", sequencer->noise() ? "measured" : "measuring"},
          {"noise_profile",
           sequencer->noise() ? protocol::ToJson(*sequencer->noise()) : nlohmann::json()},
          {"current", sequencer->busy() ? current : nlohmann::json()},
          {"samples",
           {{"used", t.used}, {"flagged", t.flagged}, {"outliers", t.outliers}, {"lost", t.lost}}},
          {"moves", MovesJson()},
          {"models", model_status}};
}

nlohmann::json DevicePipeline::ResultJson() const {
  nlohmann::json model_results = nlohmann::json::object();
  for (const ModelPipeline& m : models) model_results[m.model->name()] = m.ResultJson();
  nlohmann::json free_result;
  if (free) {
    free_result = free->ResultJson(records_used.size());
    model_results = free_result["models"];
    free_result.erase("models");
  }
  return {{"poses", poses},
          {"pose_source", free ? "free" : "announced"},
          {"free", free_result},
          {"samples",
           {{"used", sequencer->totals().used},
            {"flagged", sequencer->totals().flagged},
            {"outliers", sequencer->totals().outliers},
            {"lost", sequencer->totals().lost}}},
          {"captured", sequencer->captured()},
          {"rejected", sequencer->rejected()},
          {"moves", MovesJson()},
          {"models", model_results}};
}

}  // namespace turncal::daemon
