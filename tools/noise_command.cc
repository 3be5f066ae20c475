#include "tools/noise_command.h"

#include <fmt/format.h>

#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <fstream>
#include <map>
#include <memory>
#include <nlohmann/json.hpp>
#include <optional>
#include <sstream>
#include <thread>
#include <tuple>

#include "core/analysis/allan.h"
#include "core/analysis/allan_edf.h"
#include "daemon/state/atomic_file.h"
#include "protocol/noise_json.h"
#include "tools/client_connection.h"
#include "tools/help_text.h"
#include "tools/noise_exports.h"
#include "tools/noise_input.h"

namespace turncal::tools {

namespace {

struct NoiseArgs {
  NoiseInputArgs input;
  std::string svg;
  bool json = false;
  // --live DEVICE: a rest measured by turncald ({"cmd":"noise"}).
  std::string live, socket = DefaultSocketPath();
  double seconds = 60.0;
  bool stop_only = false;
  // Exports (tools/noise_exports.h).
  std::string kalibr, kalibr_topic = "/imu0", station;
};

// Writes the Kalibr and [station] exports asked for; false (after saying why) when one cannot be.
bool WriteExports(const NoiseArgs& args, const nlohmann::json& axes, const std::string& source) {
  std::string error;
  if (!args.kalibr.empty()) {
    const std::string yaml = KalibrImuYaml(axes, source, args.kalibr_topic, &error);
    if (yaml.empty() || !daemon::WriteFileAtomically(args.kalibr, yaml, &error)) {
      fmt::print(stderr, "turncal noise: --kalibr: {}\n", error);
      return false;
    }
  }
  if (!args.station.empty()) {
    const std::string toml = StationNoiseToml(axes, source, &error);
    if (toml.empty() || !daemon::WriteFileAtomically(args.station, toml, &error)) {
      fmt::print(stderr, "turncal noise: --station: {}\n", error);
      return false;
    }
  }
  return true;
}

void PrintExportsWritten(const NoiseArgs& args) {
  if (!args.kalibr.empty()) fmt::print("Kalibr imu.yaml: {}\n", args.kalibr);
  if (!args.station.empty()) fmt::print("[station] noise prior: {}\n", args.station);
}

// The plot: log-log Allan deviation per triad, the points and the fitted model's curve.
std::string Svg(const std::vector<RestNoiseAxis>& results) {
  std::vector<std::string> triads;
  for (const auto& r : results)
    if (std::find(triads.begin(), triads.end(), r.triad) == triads.end()) triads.push_back(r.triad);
  const double W = 420, H = 320, L = 70, B = 40, T = 30, R = 15;
  std::string o = fmt::format(
      "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{}\" height=\"{}\" "
      "font-family=\"sans-serif\" font-size=\"11\">\n<rect width=\"100%\" height=\"100%\" "
      "fill=\"white\"/>\n",
      W * static_cast<double>(triads.size()), H);
  const char* colors[3] = {"#c0392b", "#27ae60", "#2c6fbb"};
  for (std::size_t k = 0; k < triads.size(); ++k) {
    double tmin = INFINITY, tmax = 0, amin = INFINITY, amax = 0;
    for (const auto& r : results) {
      if (r.triad != triads[k]) continue;
      for (const auto& p : r.points) {
        if (!(p.adev > 0)) continue;
        tmin = std::min(tmin, p.tau_s), tmax = std::max(tmax, p.tau_s);
        amin = std::min(amin, p.adev), amax = std::max(amax, p.adev);
      }
    }
    if (!(tmax > tmin) || !(amax > amin) || !(amin > 0)) continue;
    const double lx0 = std::floor(std::log10(tmin)), lx1 = std::ceil(std::log10(tmax));
    const double ly0 = std::floor(std::log10(amin)), ly1 = std::ceil(std::log10(amax));
    const double x0 = W * static_cast<double>(k);
    auto X = [&](double t) { return x0 + L + (std::log10(t) - lx0) / (lx1 - lx0) * (W - L - R); };
    auto Y = [&](double a) { return H - B - (std::log10(a) - ly0) / (ly1 - ly0) * (H - B - T); };
    o +=
        fmt::format("<text x=\"{}\" y=\"18\" font-weight=\"bold\">{} Allan deviation ({})</text>\n",
                    x0 + L, triads[k], RestNoiseUnit(triads[k]));
    o += fmt::format(
        "<rect x=\"{}\" y=\"{}\" width=\"{}\" height=\"{}\" fill=\"none\" stroke=\"#888\"/>\n",
        x0 + L, T, W - L - R, H - B - T);
    for (double e = lx0; e <= lx1; ++e) {
      o += fmt::format("<text x=\"{:.1f}\" y=\"{}\" text-anchor=\"middle\">1e{}</text>\n",
                       X(std::pow(10, e)), H - B + 14, e);
    }
    for (double e = ly0; e <= ly1; ++e) {
      o += fmt::format("<text x=\"{}\" y=\"{:.1f}\" text-anchor=\"end\">1e{}</text>\n", x0 + L - 4,
                       Y(std::pow(10, e)) + 4, e);
    }
    o += fmt::format("<text x=\"{}\" y=\"{}\" text-anchor=\"middle\">cluster time (s)</text>\n",
                     x0 + L + (W - L - R) / 2, H - 6);
    for (const auto& r : results) {
      if (r.triad != triads[k]) continue;
      const char* c = colors[r.axis];
      for (const auto& p : r.points) {
        if (!(p.adev > 0)) continue;
        o += fmt::format("<circle cx=\"{:.1f}\" cy=\"{:.1f}\" r=\"2\" fill=\"{}\"/>\n", X(p.tau_s),
                         Y(p.adev), c);
        // The 68 % interval, cut at the plot's edges.
        const double lo = std::max(p.ci68.low, std::pow(10, ly0));
        const double hi = std::min(p.ci68.high, std::pow(10, ly1));
        if (lo > 0 && hi > lo) {
          o += fmt::format(
              "<line x1=\"{0:.1f}\" x2=\"{0:.1f}\" y1=\"{1:.1f}\" y2=\"{2:.1f}\" stroke=\"{3}\" "
              "stroke-opacity=\"0.5\"/>\n",
              X(p.tau_s), Y(lo), Y(hi), c);
        }
      }
      if (r.fit.ok) {
        std::string path;
        for (int i = 0; i <= 60; ++i) {
          const double t =
              std::pow(10, std::log10(tmin) + (std::log10(tmax) - std::log10(tmin)) * i / 60);
          path += fmt::format("{}{:.1f},{:.1f}", i ? " L" : "M", X(t), Y(r.fit.Adev(t)));
        }
        o += fmt::format("<path d=\"{}\" fill=\"none\" stroke=\"{}\" stroke-width=\"1.2\"/>\n",
                         path, c);
      }
      if (r.ieee.ok) {  // IEEE 952's five terms, dashed
        std::string path;
        for (int i = 0; i <= 60; ++i) {
          const double t =
              std::pow(10, std::log10(tmin) + (std::log10(tmax) - std::log10(tmin)) * i / 60);
          path += fmt::format("{}{:.1f},{:.1f}", i ? " L" : "M", X(t), Y(r.ieee.Adev(t)));
        }
        o += fmt::format(
            "<path d=\"{}\" fill=\"none\" stroke=\"{}\" stroke-width=\"1\" "
            "stroke-dasharray=\"4 3\"/>\n",
            path, c);
      }
      o += fmt::format(
          "<text x=\"{}\" y=\"{}\" fill=\"{}\">{}: dots data, line turncald, dashes "
          "IEEE</text>\n",
          X(tmax) - 215, T + 14 + 13 * r.axis, c, "xyz"[r.axis]);
    }
  }
  return o + "</svg>\n";
}

// The codes Run returns.
constexpr Manual kNoiseManual = {
    "The overlapping Allan deviation of a static recording, per triad and axis, with its 68 % "
    "and 95 % intervals (from the equivalent degrees of freedom of the noise type each cluster "
    "time shows), the overlapping Hadamard deviation (which a rate ramp or a drift does not "
    "bias), and the noise model fitted to it: white-noise density N, a Gauss-Markov bias "
    "instability (sigma, tau), a random walk, and the IEEE flat-bottom figure; and IEEE Std "
    "952-2020's five terms -- quantisation Q, random walk N, bias instability B, rate random "
    "walk K, rate ramp R -- each with its sigma and 95 % interval, in SI and the datasheet's "
    "units (deg/sqrt(h), deg/h, ug/sqrt(Hz) ...), by a generalised least squares that allows "
    "for the Allan variances' correlation. --kalibr writes Kalibr's imu.yaml, --station the "
    "[station] noise prior. The input is "
    "read as a stream: hours of recording take the memory of a minute's (docs/NOISE.md); a "
    "progress line shows on a terminal. Record the sensor at rest for several times the "
    "longest correlation time you care about; use --from/--to to keep only the rest. The "
    "fitted values go into turncald.toml's [station] as the noise prior: acc_noise_density, "
    "acc_bias_instability (GM sigma), bias_tau_s (GM tau), acc_random_walk and the mag_ "
    "equivalents (docs/ACCURACY.md \"Drift\").",
    "turncal noise rest.tcap --svg rest-allan.svg\n"
    "turncal noise imu.bin --protocol mip --to 600 --json\n"
    "turncal noise rest10h.tcap --triad acc,gyr      # leave the magnetometer out\n"
    "turncal noise imu.npy --triad acc,gyr           # columns t ax ay az gx gy gz\n"
    "turncal noise xsens_acc.mat --triad acc --to 45   # imu_tk's text columns (raw counts)\n"
    "turncal noise --live imu1 --seconds 3600          # turncald measures imu1's rest\n"
    "turncal noise rest10h.tcap --kalibr imu.yaml --station prior.toml",
    "0 done; 1 no triad with enough samples, or the plot or an export cannot be written; 2 the "
    "input "
    "cannot be read or a command-line mistake",
    "docs/NOISE.md, docs/ACCURACY.md (the noise model), SENSORS.md"};

void PrintNoiseJson(const NoiseArgs& args, const NoiseInput& input,
                    const std::vector<RestNoiseAxis>& results) {
  const nlohmann::json out = RestNoiseAxesJson(results);
  fmt::print("{}\n", nlohmann::json{{"source", args.input.file},
                                    {"device", input.source},
                                    {"bytes", input.bytes},
                                    {"read_s", input.seconds},
                                    {"skipped_lines", input.skipped},
                                    {"axes", out}}
                         .dump());
}

void PrintNoiseText(const NoiseArgs& args, const NoiseInput& input,
                    const std::vector<RestNoiseAxis>& results) {
  const RestNoiseAxis& first = results.front();
  fmt::print("{}{}: {} samples at {:.4g} Hz ({:.1f} s){}{}; read and summed in {:.2f} s\n",
             args.input.file, input.source.empty() ? "" : " (" + input.source + ")", first.samples,
             first.rate_hz, static_cast<double>(first.samples) / first.rate_hz,
             input.skipped ? fmt::format(", {} lines skipped", input.skipped) : "",
             first.gaps ? fmt::format(", {} gaps (lost samples)", first.gaps) : "", input.seconds);
  fmt::print("\n{:<5} {:<4} {:>13} {:>13} {:>10} {:>13} {:>13} {:>10} {:>8}\n", "triad", "axis",
             "white N", "GM sigma", "GM tau s", "random walk", "flat bottom B", "at tau s",
             "fit err");
  for (const auto& r : results) {
    fmt::print("{:<5} {:<4} {:>13.4g} {:>13.4g} {:>10.4g} {:>13.4g} {:>13.4g} {:>10.3g} {:>8.3f}\n",
               r.triad, std::string(1, "xyz"[r.axis]), r.fit.white_density, r.fit.gm_sigma,
               r.fit.gm_tau_s, r.fit.random_walk, r.fit.bias_instability,
               r.fit.bias_instability_tau_s, r.fit.rms_log_error);
  }
  fmt::print("\nIEEE 952 terms, value +- 1 sigma (< the 95 % upper bound where not resolved):\n{}",
             IeeeTermsText(RestNoiseAxesJson(results)));
  fmt::print("\nWarm-up from the first sample (bias = settled + amplitude e^(-t/tau)):\n{}",
             WarmUpText(RestNoiseAxesJson(results)));
  // The Allan deviation at the decades, with its 68 % interval.
  fmt::print("\nAllan deviation (68 % interval) at each decade of cluster time:\n");
  for (const auto& r : results) {
    std::string line = fmt::format("{:<5} {:<4}", r.triad, std::string(1, "xyz"[r.axis]));
    double next = 0.0;
    for (const auto& p : r.points) {
      if (p.tau_s < next * 0.999) continue;
      line += fmt::format("  {:.3g} s: {:.3g} ({:.3g}-{:.3g})", p.tau_s, p.adev, p.ci68.low,
                          p.ci68.high);
      next = std::pow(10.0, std::floor(std::log10(p.tau_s) + 1e-9) + 1);
    }
    fmt::print("{}\n", line);
  }
  fmt::print(
      "\nUnits: N in unit/sqrt(Hz) (a mean over T s has variance N^2/(2T)); GM sigma in the unit; "
      "random walk in unit/sqrt(s); B = min Allan deviation / 0.664 (IEEE's flat-bottom "
      "reading; the fitted IEEE B is above). acc m/s^2, gyr rad/s, mag Gauss. The IEEE terms' N "
      "is the two-sided density (white N / sqrt(2)). A correlation time or random walk beyond a "
      "few times the longest "
      "cluster time ({:.3g} s) is an extrapolation: record a longer rest. --json gives every "
      "point with its 68 % and 95 % intervals and the Hadamard deviation.\n",
      first.fit.longest_tau_s);
  if (!args.svg.empty()) fmt::print("plot: {}\n", args.svg);
  PrintExportsWritten(args);
}

// A live rest: turncald sums the device's samples for --seconds (or, with --stop, ends a
// measurement already running); the answer printed as the file's would be.
int RunLive(const NoiseArgs& args) {
  ClientConnection client;
  std::string error;
  if (!client.Connect(args.socket, &error)) {
    fmt::print(stderr, "turncal noise: {}\n", error);
    return 2;
  }
  auto request = [&](const char* action) -> std::optional<nlohmann::json> {
    auto r = client.Request({{"cmd", "noise"}, {"device", args.live}, {"action", action}}, &error);
    if (r && r->value("class", "") == "ERROR") {
      error = r->value("message", r->dump());
      return std::nullopt;
    }
    return r;
  };
  if (!args.stop_only) {
    if (!request("start")) {
      fmt::print(stderr, "turncal noise: {}\n", error);
      return 2;
    }
    const bool progress =
        args.input.progress == "always" || (args.input.progress == "auto" && isatty(2) != 0);
    const auto start = std::chrono::steady_clock::now();
    auto next = start;
    for (;;) {
      const double elapsed =
          std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
      if (elapsed >= args.seconds) break;
      std::this_thread::sleep_for(std::chrono::milliseconds(200));
      if (!progress || std::chrono::steady_clock::now() < next) continue;
      next += std::chrono::seconds(5);
      const auto status = request("status");
      if (!status) {
        fmt::print(stderr, "turncal noise: {}\n", error);
        return 1;
      }
      fmt::print(stderr, "turncal noise: {}: {:.0f} of {:.0f} s, {} samples, {:.1f} s of data\n",
                 args.live, elapsed, args.seconds, status->value("samples", 0),
                 status->value("seconds", 0.0));
    }
  }
  const auto result = request("stop");
  if (!result) {
    fmt::print(stderr, "turncal noise: {}\n", error);
    return 1;
  }
  if (!(*result)["axes"].empty() && !WriteExports(args, (*result)["axes"], "--live " + args.live)) {
    return 1;
  }
  if (args.json) {
    fmt::print("{}\n", result->dump());
    return (*result)["axes"].empty() ? 1 : 0;
  }
  fmt::print("{} (live, turncald): {} samples, {:.1f} s of data since {}{}\n", args.live,
             result->value("samples", 0), result->value("seconds", 0.0),
             result->value("started", ""),
             result->contains("file") ? "; saved in " + (*result)["file"].get<std::string>() : "");
  if (result->contains("warning"))
    fmt::print("warning: {}\n", (*result)["warning"].get<std::string>());
  fmt::print("\n{:<5} {:<4} {:>13} {:>13} {:>10} {:>13} {:>13} {:>10}\n", "triad", "axis",
             "white N", "GM sigma", "GM tau s", "random walk", "flat bottom B", "at tau s");
  for (const auto& a : (*result)["axes"]) {
    fmt::print("{:<5} {:<4} {:>13.4g} {:>13.4g} {:>10.4g} {:>13.4g} {:>13.4g} {:>10.3g}\n",
               a.value("triad", ""), a.value("axis", ""), a.value("white_density", 0.0),
               a.value("gauss_markov_sigma", 0.0), a.value("gauss_markov_tau_s", 0.0),
               a.value("random_walk", 0.0), a.value("bias_instability", 0.0),
               a.value("bias_instability_tau_s", 0.0));
  }
  if ((*result)["axes"].empty()) {
    fmt::print(stderr, "turncal noise: {} sent too few samples to analyse\n", args.live);
    return 1;
  }
  fmt::print("\nIEEE 952 terms, value +- 1 sigma (< the 95 % upper bound where not resolved):\n{}",
             IeeeTermsText((*result)["axes"]));
  PrintExportsWritten(args);
  return 0;
}

int Run(const NoiseArgs& args) {
  if (!args.live.empty()) return RunLive(args);
  if (args.input.file.empty()) {
    fmt::print(stderr, "turncal noise: give a file, or --live DEVICE\n");
    return 2;
  }
  NoiseInput input;
  if (const int code = ReadNoiseInput(args.input, &input); code != 0) return code;
  const std::vector<RestNoiseAxis> results = AnalyseRestNoise(input.noise);
  if (results.empty()) {
    fmt::print(stderr, "turncal noise: '{}' has no triad with enough samples in the window\n",
               args.input.file);
    return 1;
  }
  std::string error;
  if (!args.svg.empty() && !daemon::WriteFileAtomically(args.svg, Svg(results), &error)) {
    fmt::print(stderr, "turncal noise: {}\n", error);
    return 1;
  }
  if (!WriteExports(args, RestNoiseAxesJson(results), args.input.file)) return 1;
  if (args.json) {
    PrintNoiseJson(args, input, results);
  } else {
    PrintNoiseText(args, input, results);
  }
  return 0;
}

}  // namespace

void AddNoiseCommand(CLI::App* app) {
  auto args = std::make_shared<NoiseArgs>();
  auto* cmd = app->add_subcommand(
      "noise",
      "Allan deviation of a static recording per triad and axis, with the fitted noise model "
      "(white density, Gauss-Markov bias instability, random walk)");
  SetManual(cmd, kNoiseManual);
  cmd->add_option("file", args->input.file,
                  "a .tcap capture, a raw device stream (with --protocol), a NumPy .npy array or "
                  "text columns: time in s then x y z per triad (imu_tk's .mat files, CSV)");
  cmd->add_option(
      "--live", args->live,
      "instead of a file: turncald measures this device's rest live for --seconds "
      "({\"cmd\":\"noise\"}); the result is also saved in its state directory's rest_noise/");
  cmd->add_option("--seconds", args->seconds, "with --live: how long to measure")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  cmd->add_flag("--stop", args->stop_only,
                "with --live: end a measurement already running and print it");
  cmd->add_option("--socket", args->socket, "with --live: turncald's socket ($TURNCAL_SOCKET)");
  cmd->add_option("--protocol", args->input.protocol,
                  "raw streams: mip | gx2 | xbus | xbus-legacy");
  cmd->add_option("--triad", args->input.text_triads,
                  "text columns and .npy arrays: acc | gyr | mag, or several in column order "
                  "(acc,gyr: time, then acc x y z, then gyr x y z; default acc); captures and "
                  "raw streams: only these triads (default every one the device sends)")
      ->delimiter(',')
      ->check(CLI::IsMember({"acc", "gyr", "mag"}));
  cmd->add_option("--progress", args->input.progress,
                  "progress on standard error: auto (when it is a terminal) | always | never")
      ->check(CLI::IsMember({"auto", "always", "never"}))
      ->capture_default_str();
  cmd->add_option("--scale", args->input.text_scale,
                  "text columns: multiply the values by this (e.g. counts to m/s^2)")
      ->capture_default_str();
  cmd->add_option("--device", args->input.device, "captures: the device (default: the first)");
  cmd->add_option("--from", args->input.from_s, "seconds from the first sample to start at")
      ->check(CLI::NonNegativeNumber);
  cmd->add_option("--to", args->input.to_s,
                  "seconds from the first sample to stop at (the rest only)")
      ->check(CLI::PositiveNumber);
  cmd->add_option("--svg", args->svg, "write the log-log plot with the fitted lines here");
  cmd->add_flag("--json", args->json,
                "JSON: the fits (turncald's model and IEEE 952's terms with sigma) and every Allan "
                "point per axis");
  cmd->add_option("--kalibr", args->kalibr,
                  "write Kalibr's imu.yaml here: noise densities (IEEE N) and random walks (IEEE "
                  "K), the units beside each value");
  cmd->add_option("--kalibr-topic", args->kalibr_topic, "with --kalibr: the rostopic it names")
      ->capture_default_str();
  cmd->add_option("--station", args->station,
                  "write turncald.toml's [station] noise prior here (acc_noise_density, "
                  "acc_bias_instability, bias_tau_s, acc_random_walk, mag_ ...)");
  cmd->callback([args] { throw CLI::RuntimeError(Run(*args)); });
}

}  // namespace turncal::tools
