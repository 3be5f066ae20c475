#include "montecarlo/free_montecarlo.h"

#include <fmt/format.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <filesystem>
#include <map>
#include <memory>
#include <mutex>
#include <nlohmann/json.hpp>
#include <optional>
#include <random>
#include <thread>

#include "core/estimation/free_calibrator.h"
#include "core/estimation/free_motion.h"
#include "core/estimation/sensor_class.h"
#include "core/models/free_common.h"
#include "daemon/station/free_pipeline.h"
#include "daemon/station/replay_once.h"
#include "montecarlo/parallel_runs.h"
#include "protocol/calibration_json.h"
#include "sim/capture.h"
#include "sim/free_truth.h"
#include "sim/tumble.h"

namespace turncal::montecarlo {
namespace {

// The engine: Run prepares the station and the model, runs the tumbles on `jobs` threads, each
// one Simulate -> Replay -> Truth -> Score, and summarises them.
class FreeMonteCarlo {
 public:
  explicit FreeMonteCarlo(const FreeMonteCarloOptions& options) : o_(options) {}

  FreeMonteCarloSummary Run() {
    FreeMonteCarloSummary s;
    if (!Prepare(&s.error)) return s;
    for (const auto& p : model_->parameters()) parameters_.push_back(p.name);
    s.parameters = parameters_;
    s.runs = RunAll();
    Summarise(&s);
    return s;
  }

 private:
  // The station `turncald --replay FILE --once --pose-source free` runs with this one model, and
  // the model in the context the station makes (what the truth is expressed in); false with
  // *error when an option cannot work.
  bool Prepare(std::string* error) {
    protocol_ = drivers::ParseProtocol(o_.protocol);
    station_.pose_source = daemon::PoseSource::kFree;
    station_.models = {o_.model};
    station_.sensor_class = o_.sensor_class;
    station_.sequencer.dwell_s = 1.0;
    station_.free.field_known = o_.field_known;
    if (o_.bandwidth_known) station_.free.mag_bandwidth_hz = o_.mag_bandwidth_hz;
    station_.drift_model = o_.drift == "gauss-markov";
    if (o_.warmup > 0) {
      station_.warmup_in_instabilities = o_.warmup;
      station_.warmup_tau_s = o_.warmup_tau_s;
    }
    const bool known_class = SensorClassByName(o_.sensor_class, &sensor_);
    context_ = daemon::FreeContextFor(station_, sensor_);
    model_ = MakeFreeModel(o_.model, context_, error);
    if (!protocol_ || !model_ || !known_class) {
      if (!protocol_) *error = "unknown protocol '" + o_.protocol + "'";
      if (protocol_ && model_) *error = "unknown class '" + o_.sensor_class + "'";
      return false;
    }
    if (model_->name() == "magsphere") {
      *error = "the simulator's magnetometer is an ellipsoid";
      return false;
    }
    if (o_.hand_s > 0 && model_->sensor() != SensorKind::kMagnetometer) {
      *error = "a hand's rotation calibrates the magnetometer: --model magellipsoid or accmag";
      return false;
    }
    if (o_.hand_s > 0 && !sim::HandPathByName(o_.hand_path, &hand_path_)) {
      *error = "unknown hand path '" + o_.hand_path + "' (tumble, figure8, planar)";
      return false;
    }
    if (!station_.IsValid(error)) return false;
    error->clear();
    gyro_ = model_->sensor() == SensorKind::kGyroscope;
    return true;
  }

  // Every run, `jobs` at a time, in a scratch folder removed at the end.
  std::vector<FreeRun> RunAll() {
    return RunInScratchDir<FreeRun>("turncal-free-montecarlo", o_.runs, o_.jobs, &dir_,
                                    [this](int run, FreeRun* out) { RunOne(run, out); });
  }

  // One tumble: simulated, written, replayed through the free station, its estimate scored
  // against the truth. A step that fails leaves its error in `out`.
  void RunOne(int run, FreeRun* out) {
    const std::uint64_t seed = o_.seed * 1000003 + static_cast<std::uint64_t>(run);
    sim::SimCapture capture;
    daemon::ReplayOnceOutcome replay;
    const std::string path = (dir_ / fmt::format("run-{}.tcap", run)).string();
    const bool read = sim::BuildSimCapture(SimulationFor(seed), &capture, &out->error) &&
                      sim::WriteSimCapture(capture, path, &out->error) &&
                      daemon::ReplayOnce(path, station_, "", {}, &replay, &out->error);
    std::filesystem::remove(path);
    if (!read) return;
    const nlohmann::json& device = replay.result["devices"].begin().value();
    const auto it = device["models"].find(o_.model);
    if (it == device["models"].end()) {
      out->error = "no result for the model";
      return;
    }
    const nlohmann::json& r = *it;
    // The still intervals the model used (its intervals less its values in motion; the device's
    // pose count is the records a pose-based model took, none for a magnetometer alone).
    out->intervals = r.value("intervals", 0) - r.value("motion_points", 0);
    Gate(r, out);
    if (!Truth(capture, r, out)) return;
    Score(r, out);
    if (o_.hand_s > 0 && o_.model == "magellipsoid") CompareHardIron(capture, out);
    Scored(run, *out);
  }

  // A run that reached an estimate: counted, and told to on_run.
  void Scored(int run, const FreeRun& out) {
    std::lock_guard<std::mutex> lock(mutex_);
    const int scored = ++done_;
    if (o_.on_run) o_.on_run(run, out, scored, parameters_);
  }

  // The tumble a run simulates: random orientations within the cap, the class's noise, the
  // warm-up; a gyroscope model's runs simulate a gyro12 gyro.
  sim::SimCaptureOptions SimulationFor(std::uint64_t seed) const {
    std::mt19937_64 rng(seed ^ 0x7u);
    sim::SimCaptureOptions o;
    o.protocol = *protocol_;
    o.accel_model = "accel13";
    o.mag_model = "mag13";
    if (gyro_) o.gyro_model = "gyro12";
    o.poses = sim::TumbleTablePoses(o_.orientations, o_.cap_deg, &rng);
    o.session.sensor = sensor_;
    o.session.acc_warmup = o_.warmup * sensor_.acc_bias_instability;
    o.session.mag_warmup = o_.warmup * sensor_.mag_bias_instability;
    o.session.gyr_warmup = o_.warmup * sensor_.gyr_bias_instability;
    o.session.warmup_tau_s = o_.warmup_tau_s;
    o.session.dwell_s = o_.dwell_s;
    o.session.seed = seed;
    if (o_.magnet_at_s >= 0) {
      o.session.magnet_at_s = o_.magnet_at_s;
      o.session.magnet_s = o_.magnet_s;
      o.session.magnet_peak = o_.magnet_peak;
    }
    if (o_.hand_s > 0) {
      o.poses.clear();
      sim::HandMotion hand;
      hand.path = hand_path_;
      hand.duration_s = o_.hand_s;
      hand.rate_dps = o_.hand_rate_dps;
      hand.pause_every_s = o_.hand_pause_every_s;
      hand.pause_s = o_.hand_pause_s;
      o.session.hand = hand;
      o.session.start_s = 0.0;
      o.session.mag_rate_hz = o_.mag_rate_hz;
      o.session.mag_bandwidth_hz = o_.mag_bandwidth_hz;
      o.session.mag_lag_s = o_.mag_lag_s;
      o.session.mag_noise_filtered = o_.mag_noise_filtered;
      if (o_.device_rate_hz > 0) o.session.rate_hz = o_.device_rate_hz;
    }
    return o;
  }

  // The gate's verdict on the model's result `r` and its reasons.
  static void Gate(const nlohmann::json& r, FreeRun* out) {
    out->gated = true;
    out->gate = r["gate"].value("pass", false);
    for (const auto& why : r["gate"].value("reasons", nlohmann::json::array())) {
      if (why.is_string()) out->reasons.push_back(GateReasonKind(why.get<std::string>()));
    }
  }

  // The free model's truth for the simulated sensor over the result's bias window (on the
  // session's clock: host time = capture time); false with the run's error when the result is
  // another model's or no estimate.
  bool Truth(const sim::SimCapture& capture, const nlohmann::json& r, FreeRun* out) const {
    std::optional<TimeWindow> window;
    TimeWindow host;
    if (r.contains("bias_window") && protocol::ParseTimeWindow(r["bias_window"], &host)) {
      const double offset_s = static_cast<double>(capture.offset_ns) * 1e-9;
      window = TimeWindow{host.t0_s - offset_s, host.t1_s - offset_s};
    }
    const std::string fitted = r.value("model", "");
    std::string e;
    if (fitted != o_.model || !r.value("ok", false) ||
        !sim::FreeTruth(capture, o_.model, context_, window, &out->truth, &e)) {
      out->error = fitted != o_.model      ? "fitted " + fitted + ": " + r.value("note", "")
                   : !r.value("ok", false) ? r.value("error", "no estimate")
                                           : e;
      return false;
    }
    return true;
  }

  // The estimate, its sigma (infinite where the result has none), z and the fit check's p-value.
  void Score(const nlohmann::json& r, FreeRun* out) const {
    const int n = model_->num_parameters();
    out->theta.resize(n);
    out->sigma.resize(n);
    for (int i = 0; i < n; ++i) {
      const auto& p = r["params"][model_->parameters()[static_cast<std::size_t>(i)].name];
      out->theta[i] = p["value"].get<double>();
      out->sigma[i] = p["sigma"].is_number() ? p["sigma"].get<double>() : INFINITY;
    }
    out->z = (out->theta - out->truth).cwiseQuotient(out->sigma);
    if (const auto it = r.find("norm_bias"); it != r.end() && it->is_object()) {
      for (int i = 0; i < n; ++i) {
        const auto& name = model_->parameters()[static_cast<std::size_t>(i)].name;
        if (it->contains(name) && (*it)[name].is_number()) {
          out->norm_bias_sigmas =
              std::max(out->norm_bias_sigmas, std::abs((*it)[name].get<double>()) / out->sigma[i]);
        }
      }
    }
    out->p_value = r.value("p_value", 1.0);
    out->ok = out->z.allFinite();
    if (!out->ok) out->error = "a sigma is not finite";
  }

  // The hard iron's error of the estimate and of the plain sphere and ellipsoid fits through
  // every new magnetometer value (held repeats left out, as the station does), against the same
  // truth.
  void CompareHardIron(const sim::SimCapture& capture, FreeRun* out) const {
    std::vector<Eigen::Vector3d> values;
    for (const Sample& sample : capture.session.samples) {
      if (sample.mag && (values.empty() || *sample.mag != values.back())) {
        values.push_back(*sample.mag);
      }
    }
    Eigen::Vector3d estimate, truth;
    for (int k = 0; k < 3; ++k) {
      const int i = model_->index_of(k == 0 ? "bx" : k == 1 ? "by" : "bz");
      if (i < 0) return;
      estimate[k] = out->theta[i];
      truth[k] = out->truth[i];
    }
    out->hard_iron_error = (estimate - truth).norm();
    if (const auto sphere = free::FitSphere(values)) {
      out->sphere_error = (sphere->center - truth).norm();
    }
    if (const auto ellipsoid = free::FitEllipsoid(values)) {
      out->ellipsoid_error = (ellipsoid->center - truth).norm();
    }
  }

  // RMS, median and largest of one method's hard-iron errors over the runs that have one.
  static HardIronErrors SummariseErrors(const std::vector<FreeRun>& runs, double FreeRun::*error) {
    std::vector<double> e;
    for (const FreeRun& r : runs) {
      if (r.ok && std::isfinite(r.*error)) e.push_back(r.*error);
    }
    HardIronErrors out;
    out.runs = static_cast<int>(e.size());
    if (e.empty()) return out;
    std::sort(e.begin(), e.end());
    double sum2 = 0;
    for (double x : e) sum2 += x * x;
    out.rms = std::sqrt(sum2 / static_cast<double>(e.size()));
    out.median = e[e.size() / 2];
    out.max = e.back();
    return out;
  }

  // The gate over every run it judged, then the z-scores, p-values and intervals over the runs
  // with finite z.
  void Summarise(FreeMonteCarloSummary* s) const {
    std::map<std::string, int> reasons;
    for (const FreeRun& r : s->runs) {
      s->gated += r.gated;
      s->gate_passed += r.gated && r.gate;
      for (const auto& why : r.reasons) ++reasons[why];
    }
    for (const auto& [why, count] : reasons) s->top_reasons.emplace_back(count, why);
    std::sort(s->top_reasons.rbegin(), s->top_reasons.rend());
    if (s->top_reasons.size() > 5) s->top_reasons.resize(5);
    s->z = ZScoreSummary(model_->num_parameters());
    double intervals = 0;
    const std::vector<double> p_values =
        AddSolvedRuns(s, [&](const FreeRun& r) { intervals += r.intervals; });
    if (s->solved < 2) return;
    s->intervals_mean = intervals / s->solved;
    s->hard_iron = SummariseErrors(s->runs, &FreeRun::hard_iron_error);
    s->plain_sphere = SummariseErrors(s->runs, &FreeRun::sphere_error);
    s->plain_ellipsoid = SummariseErrors(s->runs, &FreeRun::ellipsoid_error);
    std::vector<double> removed;
    for (const FreeRun& r : s->runs) {
      if (r.ok && std::isfinite(r.norm_bias_sigmas)) removed.push_back(r.norm_bias_sigmas);
    }
    if (!removed.empty()) {
      s->norm_bias_max = *std::max_element(removed.begin(), removed.end());
      s->norm_bias_median = MedianOf(std::move(removed));
    }
    s->ks = KsUniform(p_values);
    s->p_value_deciles.assign(10, 0);
    for (double p : p_values) {
      ++s->p_value_deciles[static_cast<std::size_t>(std::clamp(p, 0.0, 0.999) * 10)];
    }
  }

  const FreeMonteCarloOptions& o_;
  std::optional<drivers::Protocol> protocol_;
  daemon::StationOptions station_;
  SensorClass sensor_;
  FreeContext context_;
  std::unique_ptr<FreeModel> model_;
  std::vector<std::string> parameters_;
  bool gyro_ = false;
  sim::HandMotion::Path hand_path_ = sim::HandMotion::Path::kTumble;
  std::filesystem::path dir_;
  int done_ = 0;  // runs scored, under mutex_
  std::mutex mutex_;
};

}  // namespace

std::string GateReasonKind(const std::string& reason) {
  auto digit = [&](std::size_t i) {
    return i < reason.size() && reason[i] >= '0' && reason[i] <= '9';
  };
  std::string out;
  for (std::size_t i = 0; i < reason.size();) {
    if (digit(i) || (reason[i] == '.' && digit(i + 1))) {
      // A number: digits, a point, an exponent.
      while (digit(i) || reason[i] == '.' ||
             ((reason[i] == 'e' || reason[i] == 'E') &&
              (digit(i + 1) || ((reason[i + 1] == '-' || reason[i + 1] == '+') && digit(i + 2))))) {
        i += (reason[i] == 'e' || reason[i] == 'E') && !digit(i + 1) ? 2 : 1;
      }
      out += '#';
      continue;
    }
    out += reason[i++];
  }
  return out;
}

bool FreeMonteCarloSummary::Passed() const {
  for (int i = 0; i < z.parameters(); ++i) {
    if (!z.Honest(i)) return false;
  }
  return true;
}

FreeMonteCarloSummary RunFreeMonteCarlo(const FreeMonteCarloOptions& options) {
  return FreeMonteCarlo(options).Run();
}

}  // namespace turncal::montecarlo
