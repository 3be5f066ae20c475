// The station's free pose source (issue 22, daemon/station/free_pipeline.h): after each static
// interval a free device's models are fitted again on the solve worker, gated, and a model whose
// gate passes becomes active (written to the state directory, applied to live samples, announced).

#include <fmt/format.h>

#include <algorithm>

#include "daemon/station/station.h"
#include "drivers/transport/transport.h"
#include "protocol/free_json.h"

namespace turncal::daemon {

void Station::QueueFreeFit(std::size_t device, double t_s) {
  DeviceState& d = *devices_[device];
  auto job = std::make_shared<FreeUpdate>();
  // The worker fits copies: the loop goes on capturing meanwhile.
  Defer(
      [job, configured = d.free->configured, intervals = d.records_used, context = d.free->context,
       options = d.free->options] { job->Run(configured, intervals, context, options); },
      [this, device, job, t_s, resuming = resuming_] { ApplyFree(device, *job, t_s, resuming); });
}

void Station::ApplyFree(std::size_t device, const FreeUpdate& job, double t_s, bool resuming) {
  DeviceState& d = *devices_[device];
  if (!job.error.empty()) {
    Publish({{"class", "ERROR"}, {"device", d.name}, {"message", "free models: " + job.error}});
    return;
  }
  for (FreeModelState* m : d.free->Take(job)) {
    const FreeEstimate& fe = m->result.estimate;
    const Estimate& e = fe.estimate;
    const bool pass = e.ok && fe.gate_passed;
    if (!resuming) {
      nlohmann::json gate = {
          {"pass", pass},
          {"reasons",
           e.ok ? fe.gate_reasons : std::vector<std::string>{"no estimate: " + e.error}}};
      std::string summary =
          e.ok ? fmt::format("{}: {} intervals, rank {} of {}, chi2/dof {:.2f}, coverage {:.1f} %",
                             m->result.model, fe.intervals, e.rank, e.parameters.size(),
                             e.dof > 0 ? e.chi2 / e.dof : 0.0, 100 * fe.coverage.fraction())
               : fmt::format("{}: no estimate: {}", m->result.model, e.error);
      nlohmann::json event = {{"class", "ESTIMATE"},
                              {"t", t_s},
                              {"device", d.name},
                              {"model", m->requested},
                              {"fitted", m->result.model},
                              {"pose_source", "free"},
                              {"poses", fe.intervals},
                              {"intervals", fe.intervals},
                              {"moves", MovesUsed(fe)},
                              {"summary", summary},
                              {"precision", m->PrecisionJson(d.gate)},
                              {"gate", gate}};
      if (!m->result.note.empty()) event["note"] = m->result.note;
      if (m->advice) event["advice"] = m->advice->text;
      Publish(event);
    }
    if (pass && !resuming) {
      ActivateFree(d, *m, t_s, nullptr);
    } else if (pass && m->active_version > 0) {
      // Resumed: the estimate the stored version was made from, applied again.
      m->Apply(m->active_version, m->result.model, e.theta, e.covariance,
               m->upstream ? m->upstream->model : std::string(),
               m->upstream ? m->upstream->estimate.estimate.theta : Eigen::VectorXd(),
               fe.bias_window_host, d.free->context);
    }
  }
}

void Station::ActivateFree(DeviceState& d, FreeModelState& m, double t_s,
                           const nlohmann::json& override_who) {
  ++m.active_version;
  protocol::FreeCalibrationInput in;
  in.device = d.name;
  in.version = m.active_version;
  in.result = &m.result;
  in.upstream = m.upstream ? &*m.upstream : nullptr;
  in.advice = m.advice;
  in.context = d.free->context;
  in.options = d.free->options;
  in.sensor_class = options_.sensor_class;
  in.intervals.assign(d.records_used.begin(),
                      d.records_used.begin() + static_cast<std::ptrdiff_t>(std::min(
                                                   m.estimate_intervals, d.records_used.size())));
  in.identity = d.identity;
  nlohmann::json calibration = protocol::FreeCalibrationJson(in);
  calibration["requested"] = m.requested;
  calibration["time"] = drivers::UtcNowIso8601();
  if (!override_who.is_null()) calibration["override"] = override_who;
  nlohmann::json event = {{"class", "CALIBRATION_ACTIVE"},
                          {"t", t_s},
                          {"device", d.name},
                          {"model", m.requested},
                          {"fitted", m.result.model},
                          {"version", m.active_version},
                          {"poses", m.result.estimate.intervals},
                          {"intervals", m.result.estimate.intervals},
                          {"moves", MovesUsed(m.result.estimate)}};
  if (!override_who.is_null()) event["override"] = override_who;
  const Estimate& e = m.result.estimate.estimate;
  PersistCalibration(
      d, m.requested, std::move(calibration), std::move(event),
      [&m, version = m.active_version, model = m.result.model, theta = e.theta,
       covariance = e.covariance, window = m.result.estimate.bias_window_host,
       upstream = m.upstream ? m.upstream->model : std::string(),
       upstream_theta = m.upstream ? m.upstream->estimate.estimate.theta : Eigen::VectorXd(),
       context = d.free->context] {
        if (version > m.applied_version) {
          m.Apply(version, model, theta, covariance, upstream, upstream_theta, window, context);
        }
      });
}

}  // namespace turncal::daemon
