#include "tools/free_montecarlo.h"

#include <fmt/format.h>
#include <fmt/ranges.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <filesystem>
#include <map>
#include <mutex>
#include <nlohmann/json.hpp>
#include <random>
#include <thread>

#include "core/estimation/free_calibrator.h"
#include "core/estimation/sensor_class.h"
#include "daemon/free_pipeline.h"
#include "daemon/replay_once.h"
#include "protocol/calibration_json.h"
#include "sim/capture.h"
#include "sim/free_truth.h"
#include "sim/tumble.h"
#include "tools/ks_uniform.h"

namespace turncal::tools {
namespace {

struct Outcome {
  bool ok = false;
  std::string error;
  Eigen::VectorXd z;
  double p_value = 1.0;
  bool gate = false;
  bool gated = false;                // the model's gate judged the run (pass or refuse)
  std::vector<std::string> reasons;  // why it refused, digits left out (to count alike ones)
  int intervals = 0;
};

// A gate reason with its numbers left out: refusals for the same cause count together.
std::string ReasonKind(const std::string& reason) {
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

}  // namespace

int RunFreeMonteCarlo(const FreeMonteCarloArgs& args) {
  std::string error;
  const auto protocol = drivers::ParseProtocol(args.protocol);
  SensorClass sensor;
  // The station turncald --replay FILE --once --pose-source free runs, with this one model.
  daemon::StationOptions station;
  station.pose_source = daemon::PoseSource::kFree;
  station.models = {args.model};
  station.sensor_class = args.sensor_class;
  station.sequencer.dwell_s = 1.0;
  station.free.field_known = args.field_known;
  station.drift_model = args.drift == "gauss-markov";
  if (args.warmup > 0) {
    station.warmup_in_instabilities = args.warmup;
    station.warmup_tau_s = args.warmup_tau_s;
  }
  const bool known_class = SensorClassByName(args.sensor_class, &sensor);
  // The free models' context as the station makes it: what the truth is expressed in.
  const FreeContext context = daemon::FreeContextFor(station, sensor);
  auto model = MakeFreeModel(args.model, context, &error);
  if (!protocol || !model || !known_class) {
    fmt::print(stderr, "turncal free-montecarlo: {}\n",
               !protocol ? "unknown protocol '" + args.protocol + "'"
               : !model  ? error
                         : "unknown class '" + args.sensor_class + "'");
    return 2;
  }
  if (model->name() == "magsphere") {
    fmt::print(stderr, "turncal free-montecarlo: the simulator's magnetometer is an ellipsoid\n");
    return 2;
  }
  if (!station.IsValid(&error)) {
    fmt::print(stderr, "turncal free-montecarlo: {}\n", error);
    return 2;
  }
  const bool gyro = model->sensor() == SensorKind::kGyroscope;
  const int N = model->num_parameters();
  const auto dir = std::filesystem::temp_directory_path() /
                   fmt::format("turncal-free-montecarlo-{}", static_cast<long>(::getpid()));
  std::filesystem::create_directories(dir);

  std::vector<Outcome> outcomes(static_cast<std::size_t>(args.runs));
  std::atomic<int> next{0}, done{0};
  std::mutex print_mutex;
  auto worker = [&] {
    for (int run = next++; run < args.runs; run = next++) {
      Outcome& out = outcomes[static_cast<std::size_t>(run)];
      const std::uint64_t seed = args.seed * 1000003 + static_cast<std::uint64_t>(run);
      std::mt19937_64 rng(seed ^ 0x7u);
      sim::SimCaptureOptions o;
      o.protocol = *protocol;
      o.accel_model = "accel13";
      o.mag_model = "mag13";
      if (gyro) o.gyro_model = "gyro12";
      o.poses = sim::TumbleTablePoses(args.orientations, args.cap_deg, &rng);
      o.session.sensor = sensor;
      o.session.acc_warmup = args.warmup * sensor.acc_bias_instability;
      o.session.mag_warmup = args.warmup * sensor.mag_bias_instability;
      o.session.gyr_warmup = args.warmup * sensor.gyr_bias_instability;
      o.session.warmup_tau_s = args.warmup_tau_s;
      o.session.dwell_s = args.dwell_s;
      o.session.seed = seed;
      sim::SimCapture capture;
      std::string e;
      const std::string path = (dir / fmt::format("run-{}.tcap", run)).string();
      daemon::ReplayOnceOutcome replay;
      const bool read = sim::BuildSimCapture(o, &capture, &e) &&
                        sim::WriteSimCapture(capture, path, &e) &&
                        daemon::ReplayOnce(path, station, "", {}, &replay, &e);
      std::filesystem::remove(path);
      if (!read) {
        out.error = e;
        continue;
      }
      const nlohmann::json& device = replay.result["devices"].begin().value();
      out.intervals = device.value("poses", 0);
      const auto it = device["models"].find(args.model);
      if (it == device["models"].end()) {
        out.error = "no result for the model";
        continue;
      }
      const nlohmann::json& r = *it;
      out.gated = true;
      out.gate = r["gate"].value("pass", false);
      for (const auto& why : r["gate"].value("reasons", nlohmann::json::array())) {
        if (why.is_string()) out.reasons.push_back(ReasonKind(why.get<std::string>()));
      }
      // The bias window on the session's clock (host time = capture time).
      std::optional<TimeWindow> window;
      TimeWindow host;
      if (r.contains("bias_window") && protocol::ParseTimeWindow(r["bias_window"], &host)) {
        const double offset_s = static_cast<double>(capture.offset_ns) * 1e-9;
        window = TimeWindow{host.t0_s - offset_s, host.t1_s - offset_s};
      }
      Eigen::VectorXd truth;
      const std::string fitted = r.value("model", "");
      if (fitted != args.model || !r.value("ok", false) ||
          !sim::FreeTruth(capture, args.model, context, window, &truth, &e)) {
        out.error = fitted != args.model    ? "fitted " + fitted + ": " + r.value("note", "")
                    : !r.value("ok", false) ? r.value("error", "no estimate")
                                            : e;
        continue;
      }
      Eigen::VectorXd theta(N), sigma(N);
      for (int i = 0; i < N; ++i) {
        const auto& p = r["params"][model->parameters()[static_cast<std::size_t>(i)].name];
        theta[i] = p["value"].get<double>();
        sigma[i] = p["sigma"].is_number() ? p["sigma"].get<double>() : INFINITY;
      }
      out.z = (theta - truth).cwiseQuotient(sigma);
      if (args.verbose) {
        std::lock_guard<std::mutex> lock(print_mutex);
        for (int i = 0; i < N; ++i) {
          fmt::print(stderr, "run {} {} est {:.9g} truth {:.9g} sigma {:.3g} z {:+.2f}\n", run,
                     model->parameters()[static_cast<std::size_t>(i)].name, theta[i], truth[i],
                     sigma[i], out.z[i]);
        }
      }
      out.p_value = r.value("p_value", 1.0);
      out.ok = out.z.allFinite();
      if (!out.ok) out.error = "a sigma is not finite";
      const int d = ++done;
      if (!args.json && d % std::max(1, args.runs / 10) == 0) {
        std::lock_guard<std::mutex> lock(print_mutex);
        fmt::print(stderr, "  {} of {} runs\n", d, args.runs);
      }
    }
  };
  std::vector<std::thread> threads;
  for (int j = 0; j < std::max(1, args.jobs); ++j) threads.emplace_back(worker);
  for (auto& t : threads) t.join();
  std::filesystem::remove_all(dir);

  Eigen::VectorXd s1 = Eigen::VectorXd::Zero(N), s2 = Eigen::VectorXd::Zero(N);
  Eigen::VectorXi beyond3 = Eigen::VectorXi::Zero(N);
  std::vector<double> p_values;
  int ok = 0, gates = 0, gated = 0;
  double intervals = 0;
  std::string first_error;
  // The gate over every run it judged (also those whose sigma is not finite: a low-coverage
  // tumble's undetermined directions), and its reasons, alike ones counted together.
  std::map<std::string, int> reasons;
  for (const auto& out : outcomes) {
    gated += out.gated;
    gates += out.gated && out.gate;
    for (const auto& why : out.reasons) ++reasons[why];
  }
  std::vector<std::pair<int, std::string>> top;
  for (const auto& [why, count] : reasons) top.emplace_back(count, why);
  std::sort(top.rbegin(), top.rend());
  if (top.size() > 5) top.resize(5);
  std::string reasons_text;
  for (const auto& [count, why] : top) reasons_text += fmt::format("  {} runs: {}\n", count, why);
  for (const auto& out : outcomes) {
    if (!out.ok) {
      if (first_error.empty()) first_error = out.error;
      continue;
    }
    ++ok;
    s1 += out.z;
    s2 += out.z.cwiseAbs2();
    for (int i = 0; i < N; ++i) beyond3[i] += std::abs(out.z[i]) > 3;
    p_values.push_back(out.p_value);
    intervals += out.intervals;
  }
  if (ok < 2) {
    fmt::print(stderr, "turncal free-montecarlo: {} of {} runs gave an estimate ({})\n", ok,
               args.runs, first_error);
    if (gated > 0) {
      fmt::print("the gate passed {} of {} runs{}\n{}", gates, gated,
                 top.empty() ? "" : "; it refused for", reasons_text);
    }
    return 1;
  }
  const Eigen::VectorXd mean = s1 / ok;
  const Eigen::VectorXd std_z = (s2 / ok - mean.cwiseAbs2()).cwiseMax(0.0).cwiseSqrt();
  const auto [ks_d, ks_p] = KsUniform(p_values);
  // The chi^2 p-values' deciles: uniform when the noise model is right (too many near 0: chi^2
  // too large; near 1: too small).
  std::vector<int> deciles(10, 0);
  for (double p : p_values) ++deciles[static_cast<std::size_t>(std::clamp(p, 0.0, 0.999) * 10)];
  int bad = 0;
  nlohmann::json rows = nlohmann::json::array();
  std::string table =
      "| param | mean z | std z | beyond 3 sigma | verdict |\n|---|---|---|---|---|\n";
  for (int i = 0; i < N; ++i) {
    const bool honest = std_z[i] >= 0.9 && std_z[i] <= 1.1 && std::abs(mean[i]) <= 0.15;
    bad += !honest;
    const std::string& name = model->parameters()[static_cast<std::size_t>(i)].name;
    rows.push_back({{"name", name},
                    {"mean_z", mean[i]},
                    {"std_z", std_z[i]},
                    {"beyond_3_sigma", beyond3[i]},
                    {"honest", honest}});
    table += fmt::format("| {} | {:+.3f} | {:.3f} | {} | {} |\n", name, mean[i], std_z[i],
                         beyond3[i], honest ? "ok" : "NOT HONEST");
  }
  if (args.json) {
    fmt::print("{}\n", nlohmann::json{{"model", args.model},
                                      {"class", args.sensor_class},
                                      {"protocol", args.protocol},
                                      {"drift", args.drift},
                                      {"warmup", args.warmup},
                                      {"runs", args.runs},
                                      {"ok", ok},
                                      {"orientations", args.orientations},
                                      {"cap_deg", args.cap_deg},
                                      {"mean_intervals", intervals / ok},
                                      {"gate_passed", gates},
                                      {"gated", gated},
                                      {"gate_reasons", top},
                                      {"ks_d", ks_d},
                                      {"ks_p", ks_p},
                                      {"p_value_deciles", deciles},
                                      {"params", rows}}
                           .dump());
  } else {
    fmt::print(
        "free {} ({} class, {}, drift {}{}), {} tumbles of {} orientations (up within {:.0f} deg "
        "of "
        "+z), "
        "each as bytes through free mode: {} estimated ({} failed{}), {:.1f} intervals on "
        "average, gate passed {} of {}\n{}\n{}\nchi^2 p-values against uniform: KS D = {:.3f}, p = "
        "{:.3g}; per tenth from 0 to 1: {}\nCriteria: std z in [0.9, 1.1] and |mean z| <= 0.15; "
        "{} of {} parameters fail.\n",
        args.model, args.sensor_class, args.protocol, args.drift,
        args.warmup > 0 ? fmt::format(", warm-up {} bias instabilities", args.warmup) : "",
        args.runs, args.orientations, args.cap_deg, ok, args.runs - ok,
        first_error.empty() ? "" : ", the first: " + first_error, intervals / ok, gates, gated,
        top.empty() ? "" : "refused for:\n" + reasons_text, table, ks_d, ks_p,
        fmt::join(deciles, " "), bad, N);
  }
  return bad == 0 ? 0 : 1;
}

void AddFreeMonteCarloCommand(CLI::App* app) {
  auto a = std::make_shared<FreeMonteCarloArgs>();
  auto* cmd = app->add_subcommand(
      "free-montecarlo",
      "repeat simulated tumbles as bytes through free mode and check the free models' sigma");
  cmd->add_option("--model", a->model, "accel9 | gyro9 | gyro9g | magellipsoid | accmag")
      ->check(CLI::IsMember({"accel9", "gyro9", "gyro9g", "magellipsoid", "accmag"}))
      ->capture_default_str();
  cmd->add_option("--class", a->sensor_class, "industrial | consumer (SENSORS.md)")
      ->check(CLI::IsMember({"industrial", "consumer"}))
      ->capture_default_str();
  cmd->add_option("--protocol", a->protocol, "mip | gx2 | xbus | xbus-legacy")
      ->capture_default_str();
  cmd->add_option("--runs", a->runs, "tumbles")
      ->check(CLI::Range(2, 100000))
      ->capture_default_str();
  cmd->add_option("--seed", a->seed, "the first run's seed")->capture_default_str();
  cmd->add_option("--jobs", a->jobs, "runs in parallel")
      ->check(CLI::Range(1, 64))
      ->capture_default_str();
  cmd->add_option("--orientations", a->orientations, "static orientations per tumble")
      ->check(CLI::Range(4, 1000))
      ->capture_default_str();
  cmd->add_option("--dwell", a->dwell_s, "seconds still per orientation")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  cmd->add_option("--cap", a->cap_deg,
                  "up within this many degrees of the table's +z (180: anywhere; small: low "
                  "coverage)")
      ->check(CLI::Range(0.0, 180.0))
      ->capture_default_str();
  cmd->add_flag(
      "--field-unknown", [a](std::int64_t) { a->field_known = false; },
      "the magnetometer models without the field's magnitude (relative scale)");
  cmd->add_option("--drift", a->drift,
                  "the station's model of the bias wander ([station] drift_model): gauss-markov "
                  "(the class's, a process in time) or independent (an offset per interval of "
                  "the class's bias instability)")
      ->check(CLI::IsMember({"gauss-markov", "independent"}))
      ->capture_default_str();
  cmd->add_option("--warmup", a->warmup,
                  "a warm-up after power-on of this many bias instabilities (every triad, the "
                  "gyroscope's too), simulated and allowed for by the station")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  cmd->add_option("--warmup-tau", a->warmup_tau_s, "the warm-up's time constant, s")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  cmd->add_flag("--verbose", a->verbose,
                "every run's estimate, truth, sigma and z per parameter on standard error");
  cmd->add_flag("--json", a->json, "one JSON object");
  cmd->callback([a] { throw CLI::RuntimeError(RunFreeMonteCarlo(*a)); });
}

}  // namespace turncal::tools
