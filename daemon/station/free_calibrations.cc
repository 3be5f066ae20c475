// A device's free models as the station's calibration set (daemon/station/free_pipeline.h,
// issue 22): after each static interval every model is fitted again on the solve worker to all of
// the device's intervals, gated, and a model whose gate passes becomes active.

#include <fmt/format.h>

#include <algorithm>
#include <cmath>

#include "core/sequencing/sequencer.h"
#include "daemon/station/device_pipeline.h"
#include "daemon/station/free_pipeline.h"
#include "daemon/station/station.h"
#include "protocol/free_json.h"

namespace turncal::daemon {

FreeCalibrations::FreeCalibrations(std::vector<std::string> configured,
                                   const StationOptions& options, const SensorClass& sensor,
                                   const GateOptions& gate)
    : configured_(std::move(configured)),
      context_(FreeContextFor(options, sensor)),
      options_(FreeOptionsFor(options, gate)) {
  // What the data carry may include a gyroscope: its moves are then its evidence.
  needs_moves_ = configured_.empty();
  std::string error;
  for (const auto& name : configured_) {
    auto model = MakeFreeModel(name, context_, &error);
    needs_moves_ = needs_moves_ || (model && model->Needs(SensorKind::kGyroscope));
    motion_.enabled = motion_.enabled || (model && model->Needs(SensorKind::kMagnetometer));
    Get(name);
  }
  // What the data carry may include a magnetometer model.
  motion_.enabled = options.free.motion && (configured_.empty() || motion_.enabled);
  motion_options_.max_points = options.free.max_motion_points;
  motion_options_.mag_bandwidth_hz = options.free.mag_bandwidth_hz;
  // A stream never still long enough for the noise meter: the class's magnetometer noise.
  const NoiseProfile class_noise = NoiseProfileForClass(sensor, 100.0, true);
  class_mag_sigma_ = *class_noise.sigma[kTriadMag];
  class_noise_source_ = fmt::format(
      "the {} class's (no noise measured: the stream was never still long enough)", sensor.name);
}

std::vector<std::string> FreeCalibrations::StoredNames() const {
  return configured_.empty() ? FreeModelNames() : configured_;
}

bool FreeCalibrations::NeedsMoves() const { return needs_moves_; }

void FreeCalibrations::Start(Sequencer& sequencer) {
  std::string error;
  sequencer.SetFree(&error);  // a new sequencer is idle, unscheduled
}

FreeModelState* FreeCalibrations::FindModel(const std::string& requested) {
  for (auto& m : models_) {
    if (m->requested == requested) return m.get();
  }
  return nullptr;
}

FreeModelState& FreeCalibrations::Get(const std::string& requested) {
  if (FreeModelState* m = FindModel(requested)) return *m;
  auto m = std::make_unique<FreeModelState>();
  m->owner = this;
  m->requested = requested;
  std::string error;
  if (auto model = MakeFreeModel(requested, context_, &error)) m->sensor = model->sensor();
  models_.push_back(std::move(m));
  return *models_.back();
}

void FreeCalibrations::OnRecord(DevicePipeline& d, const PoseRecord& /*record*/, double t_s,
                                bool resuming, CalibrationHost& host) {
  if (resuming) {
    refit_due_ = true;  // once, at the end of the resume
  } else {
    QueueFit(d, t_s, false, host);
  }
}

void FreeCalibrations::OnResumed(DevicePipeline& d, CalibrationHost& host) {
  // A resumed journal's intervals are fitted once, all together.
  if (!refit_due_) return;
  refit_due_ = false;
  double t_s = d.records_used.empty() ? 0.0 : d.records_used.back().t_end_s;
  if (!motion_.collector.values().empty()) {
    t_s = std::max(t_s, motion_.collector.values().back().t_host_s);
  }
  QueueFit(d, t_s, true, host);
}

void FreeCalibrations::OnMotionValues(DevicePipeline& /*d*/,
                                      const std::vector<MotionValue>& values) {
  if (!motion_.enabled) return;
  for (const MotionValue& v : values) motion_.collector.Add(v);
  motion_.kept += static_cast<std::int64_t>(values.size());
  motion_.kept_at_fit = motion_.kept;
  refit_due_ = true;
}

void FreeCalibrations::FlushMotion(DevicePipeline& d, CalibrationHost& host) {
  if (motion_.unjournaled.empty()) return;
  host.JournalMotion(d, std::move(motion_.unjournaled));
  motion_.unjournaled.clear();
}

void FreeCalibrations::OnSample(DevicePipeline& d, const Sample& sample, CalibrationHost& host) {
  if (!motion_.enabled) return;
  // The sequencer's sensor clock, as the still intervals' windows have it.
  std::optional<double> t_device_s;
  if (sample.t_device_s) t_device_s = d.sequencer->SensorTimeOfDevice(*sample.t_device_s);
  if (!motion_.collector.Push(sample, t_device_s)) return;
  ++motion_.kept;
  motion_.unjournaled.push_back(motion_.collector.values().back());
  const double t_s = static_cast<double>(sample.t_host_ns) * 1e-9;
  if (motion_.collector.values().size() >= FreeMotionState::kFirstFit &&
      t_s - motion_.coverage_published_s >= FreeMotionState::kCoverageEveryS) {
    PublishCoverage(d, t_s, host);
  }
  if (t_s - motion_.flushed_s >= FreeMotionState::kFlushS) {
    FlushMotion(d, host);
    motion_.flushed_s = t_s;
  }
  if (fit_in_flight_ || motion_.kept < FreeMotionState::kFirstFit) return;
  const bool doubled = motion_.kept >= 2 * motion_.kept_at_fit;
  const bool due =
      t_s - motion_.fitted_s >= FreeMotionState::kRefitS && motion_.kept > motion_.kept_at_fit;
  if (doubled || due) QueueFit(d, t_s, false, host);
}

void FreeCalibrations::OnFinish(DevicePipeline& d, CalibrationHost& host) {
  if (!motion_.enabled) return;
  FlushMotion(d, host);
  if (!motion_.collector.values().empty()) {
    PublishCoverage(d, motion_.collector.values().back().t_host_s, host);
  }
  if (motion_.kept > motion_.kept_at_fit) {
    QueueFit(d,
             motion_.collector.values().empty() ? 0.0 : motion_.collector.values().back().t_host_s,
             false, host);
  }
}

void FreeCalibrations::OnSequencerEvent(const SequencerEvent& e) {
  if (e.kind != SequencerEventKind::kSegmentSkipped) return;
  ++skipped_;
  skip_reasons_.push_back(fmt::format("at {:.2f} s: {}", e.t_s, e.reason));
  if (skip_reasons_.size() > kMaxSkipReasons) skip_reasons_.erase(skip_reasons_.begin());
}

void FreeCalibrations::QueueFit(DevicePipeline& d, double t_s, bool resuming,
                                CalibrationHost& host) {
  if (fit_in_flight_) {
    // One fit at a time: the latest data are fitted when it is done (a live stream's intervals
    // and values arrive faster than a fit of thousands of points with the drift whitened).
    pending_fit_ = PendingFit{t_s, resuming};
    return;
  }
  auto job = std::make_shared<FreeUpdate>();
  std::shared_ptr<const MotionCollector> motion;
  MotionOptions motion_options = motion_options_;
  if (motion_.enabled) {
    // Journaled before they are used (the worker runs in order).
    FlushMotion(d, host);
    motion_.flushed_s = t_s;
    motion_.kept_at_fit = motion_.kept;
    motion_.fitted_s = t_s;
    motion = std::make_shared<const MotionCollector>(motion_.collector);
    // The noise per sample: the profile's the sequencer uses (measured or the class's).
    const NoiseProfile* noise = d.sequencer->noise();
    if (!noise || !motion_options.TakeNoise(*noise)) {
      motion_options.mag_sigma = class_mag_sigma_;
      motion_options.noise_source = class_noise_source_;
    }
  }
  fit_in_flight_ = true;
  // The worker fits copies: the loop goes on capturing meanwhile.
  host.Defer(
      [job, configured = configured_, intervals = d.records_used, motion, motion_options,
       context = context_, options = options_] {
        job->Run(configured, intervals, motion.get(), motion_options, context, options);
      },
      [this, &d, job, t_s, resuming, &host] {
        fit_in_flight_ = false;
        ApplyUpdate(d, *job, t_s, resuming, host);
        if (pending_fit_) {
          const PendingFit next = *pending_fit_;
          pending_fit_.reset();
          QueueFit(d, next.t_s, next.resuming, host);
        }
      });
}

std::vector<FreeModelState*> FreeCalibrations::Take(const FreeUpdate& update) {
  std::vector<FreeModelState*> updated;
  for (const auto& name : update.models) {
    // The last result asked for under this name (an upstream fitted for another model has its
    // own name; a magellipsoid that fell back to a sphere keeps the name asked for).
    int found = -1;
    for (std::size_t i = 0; i < update.results.size(); ++i) {
      if (update.results[i].requested == name) found = static_cast<int>(i);
    }
    if (found < 0) continue;
    FreeModelState& m = Get(name);
    m.result = update.results[static_cast<std::size_t>(found)];
    m.advice = static_cast<std::size_t>(found) < update.advice.size()
                   ? update.advice[static_cast<std::size_t>(found)]
                   : std::nullopt;
    m.estimate_intervals = update.intervals;
    m.estimate_data = update.data;
    m.upstream.reset();
    std::string error;
    auto model = MakeFreeModel(m.result.model, context_, &error);
    const std::string up = model ? model->upstream() : std::string();
    for (const auto& r : update.results) {
      if (!up.empty() && r.model == up && r.estimate.estimate.ok) m.upstream = r;
    }
    updated.push_back(&m);
  }
  return updated;
}

void FreeCalibrations::TakeCoverageCorrection(const FreeUpdate& update) {
  // The magnetometer model with the most parameters that has an estimate (an ellipsoid before a
  // sphere); its correction of a raw value is the value's direction.
  const FreeModelResult* best = nullptr;
  std::shared_ptr<const FreeModel> best_model;
  for (const auto& r : update.results) {
    if (!r.estimate.estimate.ok) continue;
    std::string error;
    std::shared_ptr<const FreeModel> model = MakeFreeModel(r.model, context_, &error);
    if (!model || model->sensor() != SensorKind::kMagnetometer) continue;
    if (best &&
        best->estimate.estimate.parameters.size() >= r.estimate.estimate.parameters.size()) {
      continue;
    }
    best = &r;
    best_model = model;
  }
  if (!best) return;
  motion_.coverage.SetCorrection(
      [model = best_model, theta = best->estimate.estimate.theta](const Eigen::Vector3d& raw) {
        return model->Correct(theta, raw);
      },
      "the " + best->model + " fit");
}

void FreeCalibrations::PublishCoverage(const DevicePipeline& d, double t_s, CalibrationHost& host) {
  motion_.coverage_published_s = t_s;
  const SphereCoverage& c =
      motion_.coverage.Update(motion_.collector.values(), motion_.collector.thinned());
  nlohmann::json event = {{"class", "COVERAGE"},
                          {"t", t_s},
                          {"device", d.name},
                          {"triad", "magnetometer"},
                          {"values", c.directions},
                          {"filled", c.filled},
                          {"total", c.total},
                          {"fraction", c.fraction()},
                          {"centre", motion_.coverage.source()},
                          {"rows", CoverageRows(c)}};
  const CoverageGap gap = LargestGap(c);
  if (!gap.empty()) {
    event["gap"] = protocol::ToJson(gap);
    event["gap"]["text"] = CoverageGapText(gap, SensorKind::kMagnetometer, context_.dip_deg);
  }
  host.Publish(event);
}

void FreeCalibrations::ApplyUpdate(DevicePipeline& d, const FreeUpdate& job, double t_s,
                                   bool resuming, CalibrationHost& host) {
  if (job.motion) motion_.last = job.motion;
  if (job.error.empty() && motion_.enabled) TakeCoverageCorrection(job);
  if (!job.error.empty()) {
    host.Publish(
        {{"class", "ERROR"}, {"device", d.name}, {"message", "free models: " + job.error}});
    return;
  }
  for (FreeModelState* m : Take(job)) {
    const bool pass = m->result.estimate.estimate.ok && m->result.estimate.gate_passed;
    if (!resuming) PublishEstimate(d, *m, t_s, host);
    if (pass && !resuming) {
      host.Activate(d, *m, t_s, nullptr);
    } else if (pass && m->active_version() > 0) {
      // Resumed: the estimate the stored version was made from, applied again.
      m->ApplyResult(context_);
    }
  }
}

void FreeCalibrations::PublishEstimate(const DevicePipeline& d, const FreeModelState& m, double t_s,
                                       CalibrationHost& host) const {
  const FreeEstimate& fe = m.result.estimate;
  const Estimate& e = fe.estimate;
  nlohmann::json gate = {
      {"pass", e.ok && fe.gate_passed},
      {"reasons", e.ok ? fe.gate_reasons : std::vector<std::string>{"no estimate: " + e.error}}};
  std::string summary =
      e.ok ? fmt::format("{}: {} intervals, rank {} of {}, chi2/dof {:.2f}, coverage {:.1f} %",
                         m.result.model, fe.intervals, e.rank, e.parameters.size(),
                         e.dof > 0 ? e.chi2 / e.dof : 0.0, 100 * fe.coverage.fraction())
           : fmt::format("{}: no estimate: {}", m.result.model, e.error);
  if (e.ok && fe.motion_points > 0) {
    summary += fmt::format(" ({} of the intervals samples in motion)", fe.motion_points);
  }
  nlohmann::json event = {{"class", "ESTIMATE"},
                          {"t", t_s},
                          {"device", d.name},
                          {"model", m.requested},
                          {"fitted", m.result.model},
                          {"pose_source", "free"},
                          {"poses", fe.intervals},
                          {"intervals", fe.intervals},
                          {"moves", MovesUsed(fe)},
                          {"summary", summary},
                          {"precision", m.PrecisionJson(d.gate)},
                          {"gate", gate}};
  if (!m.result.note.empty()) event["note"] = m.result.note;
  if (m.advice) event["advice"] = m.advice->text;
  if (fe.motion_points > 0) event["motion_points"] = fe.motion_points;
  if (e.ok) {
    // The fit error as the vendors' tools give it: the norm misfit's RMS in per cent of the
    // magnitude fitted to (the field's, or gravity's).
    std::string error;
    const auto model = MakeFreeModel(m.result.model, context_, &error);
    const SensorKind triad = model && model->Needs(SensorKind::kMagnetometer)
                                 ? SensorKind::kMagnetometer
                                 : SensorKind::kAccelerometer;
    const double fit_error = model ? FitErrorPercent(fe, model->sensor(), triad, context_) : NAN;
    if (std::isfinite(fit_error)) event["fit_error_percent"] = fit_error;
    if (!fe.gap.empty()) {
      event["uncovered"] =
          CoverageGapText(fe.gap, model ? model->sensor() : m.sensor, context_.dip_deg);
    }
  }
  host.Publish(event);
}

nlohmann::json FreeCalibrations::SourceResultJson(const DevicePipeline& d) const {
  return {{"pose_source", "free"},    {"intervals", d.records_used.size()},
          {"skipped", skipped_},      {"skip_reasons", skip_reasons_},
          {"motion", motion_.Json()}, {"context", protocol::ToJson(context_)}};
}

nlohmann::json FreeCalibrations::SourceStatusJson(const DevicePipeline& d) const {
  return {{"pose_source", "free"},
          {"intervals", d.records_used.size()},
          {"skipped", skipped_},
          {"last_skip", skip_reasons_.empty() ? "" : skip_reasons_.back()},
          {"motion", motion_.Json()}};
}

nlohmann::json FreeCalibrations::NextPose(const DevicePipeline& /*d*/,
                                          const StationOptions& /*options*/) const {
  if (models_.empty()) {
    return {{"class", "NEXT_POSE"},
            {"ok", false},
            {"pose_source", "free"},
            {"error",
             "free mode: no static interval has been fitted yet; hold the device still in a "
             "first orientation"}};
  }
  nlohmann::json advice_json = nlohmann::json::array();
  bool all_pass = true;
  for (const auto& m : models_) {
    const bool pass = m->result.estimate.estimate.ok && m->result.estimate.gate_passed;
    all_pass = all_pass && pass;
    nlohmann::json a = {{"model", m->requested},
                        {"fitted", m->result.model},
                        {"gate_pass", pass},
                        {"gate_reasons", m->result.estimate.gate_reasons},
                        {"coverage", m->result.estimate.coverage.fraction()}};
    if (m->advice) {
      a["text"] = m->advice->text;
      a["sigma_ratio"] = m->advice->sigma_ratio;
    } else {
      a["text"] = nullptr;
    }
    advice_json.push_back(a);
  }
  return {{"class", "NEXT_POSE"},
          {"ok", true},
          {"pose_source", "free"},
          {"advice", advice_json},
          {"gates_pass", all_pass}};
}

}  // namespace turncal::daemon
