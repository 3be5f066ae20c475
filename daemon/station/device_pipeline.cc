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
  // The gyro bias moves with temperature: the rate test allows for the class's coefficient.
  if (so.stillness.gyr_bias_tempco_radps_per_c == 0.0) {
    so.stillness.gyr_bias_tempco_radps_per_c = sensor.gyr_bias_tempco;
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

nlohmann::json DevicePipeline::MovesJson() const {
  const MoveTracker& t = sequencer->moves();
  return {{"enabled", sequencer->options().moves.enabled},
          {"taken", t.moves()},
          {"dropped", t.dropped()},
          {"last_drop", t.last_drop()}};
}

nlohmann::json DevicePipeline::StatusJson() const {
  nlohmann::json model_status = nlohmann::json::object();
  for (std::size_t i = 0; i < calibrations->size(); ++i) {
    const Calibration& c = calibrations->at(i);
    model_status[c.name()] = c.StatusJson();
  }
  const SampleCounts& t = sequencer->totals();
  return {{"poses", poses},
          {"pose_source", calibrations->pose_source()},
          {"free", calibrations->SourceStatusJson(*this)},
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
          {"temperature", TemperatureJson()},
          {"mount", MountJson()},
          {"duplicate_serial_of",
           duplicate_serial_of.empty() ? nlohmann::json() : nlohmann::json(duplicate_serial_of)},
          {"models", model_status}};
}

nlohmann::json DevicePipeline::TemperatureJson() const {
  const SoakTracker& t = sequencer->soak_tracker();
  const double window_s = sequencer->soak() ? sequencer->soak()->window_s : SoakOptions{}.window_s;
  const std::optional<double> now = t.latest_c(), rate = t.RateCPerMin(window_s);
  nlohmann::json j = {{"temp_c", now ? nlohmann::json(*now) : nlohmann::json()},
                      {"rate_c_per_min", rate ? nlohmann::json(*rate) : nlohmann::json()},
                      {"soak", nullptr}};
  if (const auto& soak = sequencer->soak()) {
    std::string why;
    const bool settled = t.Settled(*soak, &why);
    j["soak"] = {{"setpoint_c", soak->setpoint_c},
                 {"settled", settled},
                 {"waiting", settled ? nlohmann::json() : nlohmann::json(why)}};
  }
  return j;
}

nlohmann::json DevicePipeline::ResultJson() const {
  nlohmann::json model_results = nlohmann::json::object();
  for (std::size_t i = 0; i < calibrations->size(); ++i) {
    const Calibration& c = calibrations->at(i);
    model_results[c.name()] = c.ResultJson();
  }
  return {{"poses", poses},
          {"pose_source", calibrations->pose_source()},
          {"free", calibrations->SourceResultJson(*this)},
          {"samples",
           {{"used", sequencer->totals().used},
            {"flagged", sequencer->totals().flagged},
            {"outliers", sequencer->totals().outliers},
            {"lost", sequencer->totals().lost}}},
          {"captured", sequencer->captured()},
          {"rejected", sequencer->rejected()},
          {"moves", MovesJson()},
          {"mount", MountJson()},
          {"models", model_results}};
}

std::string DevicePipeline::Serial() const {
  if (!identity.is_object()) return "";
  for (const char* key : {"serial", "device_id"}) {
    if (auto it = identity.find(key); it != identity.end() && it->is_string()) {
      return it->get<std::string>();
    }
  }
  return "";
}

}  // namespace turncal::daemon
