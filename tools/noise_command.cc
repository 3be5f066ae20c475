#include "tools/noise_command.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <map>
#include <memory>
#include <nlohmann/json.hpp>
#include <sstream>
#include <tuple>

#include "core/analysis/allan.h"
#include "core/analysis/allan_edf.h"
#include "daemon/state/atomic_file.h"
#include "tools/help_text.h"
#include "tools/noise_input.h"

namespace turncal::tools {

namespace {

struct NoiseArgs {
  NoiseInputArgs input;
  std::string svg;
  bool json = false;
};

// One Allan point with its interval, the Hadamard deviation beside it.
struct PointOut {
  std::int64_t m = 0, stride = 1;
  double tau_s = 0.0;
  int alpha = 0;  // the noise type its edf assumes (core/analysis/allan_edf.h)
  double adev = 0.0, edf = 0.0;
  VarianceInterval ci68, ci95;  // of the Allan deviation
  double hdev = NAN, hedf = 0.0;
  VarianceInterval hci68, hci95;
};

struct AxisResult {
  std::string triad;
  int axis = 0;
  std::vector<AllanPoint> points;  // the fitted ones (up to a ninth of the recording)
  std::vector<PointOut> detail;    // every one, with intervals
  std::int64_t gaps = 0;
  NoiseFit fit;
  std::size_t samples = 0;
  double rate_hz = 0.0;
};

const char* Unit(const std::string& triad) {
  return triad == "acc" ? "m/s^2" : triad == "gyr" ? "rad/s" : "G";
}

// The plot: log-log Allan deviation per triad, the points and the fitted model's curve.
std::string Svg(const std::vector<AxisResult>& results) {
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
      for (const auto& p : r.detail) {
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
                    x0 + L, triads[k], Unit(triads[k]));
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
      for (const auto& p : r.detail) {
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
      o +=
          fmt::format("<text x=\"{}\" y=\"{}\" fill=\"{}\">{}: dots measured, line fitted</text>\n",
                      X(tmax) - 150, T + 14 + 13 * r.axis, c, "xyz"[r.axis]);
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
    "instability (sigma, tau), a random walk, and the IEEE flat-bottom figure. The input is "
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
    "turncal noise xsens_acc.mat --triad acc --to 45   # imu_tk's text columns (raw counts)",
    "0 done; 1 no triad with enough samples, or the plot cannot be written; 2 the input "
    "cannot be read or a command-line mistake",
    "docs/NOISE.md, docs/ACCURACY.md (the noise model), SENSORS.md"};

// The log-log slope of the Allan variance at tau: the fitted model's, or the measured points'
// about it when there is no fit.
double AvarSlope(const NoiseFit& fit, const std::vector<PointOut>& points, std::size_t i) {
  if (fit.ok) {
    const double t = points[i].tau_s, k = 1.2;
    const double hi = fit.Adev(t * k), lo = fit.Adev(t / k);
    if (hi > 0 && lo > 0) return 2.0 * (std::log(hi) - std::log(lo)) / (2.0 * std::log(k));
  }
  const std::size_t a = i > 0 ? i - 1 : i, b = i + 1 < points.size() ? i + 1 : i;
  if (a == b || !(points[a].adev > 0) || !(points[b].adev > 0)) return -1.0;
  return 2.0 * std::log(points[b].adev / points[a].adev) /
         std::log(points[b].tau_s / points[a].tau_s);
}

VarianceInterval DeviationInterval(double deviation, double edf, double confidence) {
  const VarianceInterval v = ChiSquaredInterval(deviation * deviation, edf, confidence);
  return {std::sqrt(v.low), std::sqrt(v.high)};
}

// The Allan deviation, its intervals, the Hadamard deviation and the noise fit of every axis of
// every triad with at least 16 intervals in [from, to] (the median of the first intervals as the
// sample period).
std::vector<AxisResult> AnalyseTriads(const NoiseInput& input) {
  std::vector<AxisResult> results;
  // The axes of a triad share cluster sizes and mostly noise types: each edf once.
  std::map<std::tuple<int, int, std::int64_t, std::int64_t, std::int64_t>, double> edfs;
  auto edf = [&edfs](int alpha, int d, std::int64_t m, std::int64_t stride, std::int64_t n) {
    const auto key = std::make_tuple(alpha, d, m, stride, n);
    auto it = edfs.find(key);
    if (it == edfs.end()) it = edfs.emplace(key, OverlappingEdf(alpha, d, m, stride, n)).first;
    return it->second;
  };
  for (const TriadStream* triad : {&input.acc, &input.gyr, &input.mag}) {
    const double dt = triad->period_s();
    const std::int64_t n = triad->samples();
    if (n < 17 || !(dt > 0)) continue;
    const std::vector<StreamingAllanPoint> points = triad->allan().Points();
    for (int axis = 0; axis < 3; ++axis) {
      AxisResult r;
      r.triad = triad->name();
      r.axis = axis;
      r.samples = static_cast<std::size_t>(n);
      r.rate_hz = 1.0 / dt;
      r.gaps = triad->gaps();
      for (const StreamingAllanPoint& p : points) {
        PointOut o;
        o.m = p.m;
        o.stride = p.stride;
        o.tau_s = static_cast<double>(p.m) * dt;
        o.adev = std::sqrt(p.avar[static_cast<std::size_t>(axis)]);
        if (!p.hvar.empty()) o.hdev = std::sqrt(p.hvar[static_cast<std::size_t>(axis)]);
        r.detail.push_back(o);
        if (9 * p.m <= n) {
          r.points.push_back({o.tau_s, o.adev, static_cast<double>(n) / static_cast<double>(p.m)});
        }
      }
      r.fit = FitNoiseModel(r.points);
      for (std::size_t i = 0; i < r.detail.size(); ++i) {
        PointOut& o = r.detail[i];
        o.alpha = NoiseTypeOfSlope(AvarSlope(r.fit, r.detail, i));
        o.edf = edf(o.alpha, 2, o.m, o.stride, n);
        o.ci68 = DeviationInterval(o.adev, o.edf, 0.683);
        o.ci95 = DeviationInterval(o.adev, o.edf, 0.95);
        if (std::isfinite(o.hdev)) {
          o.hedf = edf(o.alpha, 3, o.m, o.stride, n);
          o.hci68 = DeviationInterval(o.hdev, o.hedf, 0.683);
          o.hci95 = DeviationInterval(o.hdev, o.hedf, 0.95);
        }
      }
      results.push_back(std::move(r));
    }
  }
  return results;
}

nlohmann::json Interval(const VarianceInterval& v) {
  return nlohmann::json::array({v.low, v.high});
}

void PrintNoiseJson(const NoiseArgs& args, const NoiseInput& input,
                    const std::vector<AxisResult>& results) {
  nlohmann::json out = nlohmann::json::array();
  for (const auto& r : results) {
    nlohmann::json points = nlohmann::json::array();
    for (const auto& p : r.detail) {
      nlohmann::json j = {{"tau_s", p.tau_s},
                          {"m", p.m},
                          {"stride", p.stride},
                          {"adev", p.adev},
                          {"edf", p.edf},
                          {"alpha", p.alpha},
                          {"ci68", Interval(p.ci68)},
                          {"ci95", Interval(p.ci95)}};
      if (std::isfinite(p.hdev)) {
        j["hdev"] = p.hdev;
        j["hdev_edf"] = p.hedf;
        j["hdev_ci68"] = Interval(p.hci68);
        j["hdev_ci95"] = Interval(p.hci95);
      }
      points.push_back(std::move(j));
    }
    out.push_back({{"triad", r.triad},
                   {"axis", std::string(1, "xyz"[r.axis])},
                   {"unit", Unit(r.triad)},
                   {"samples", r.samples},
                   {"rate_hz", r.rate_hz},
                   {"gaps", r.gaps},
                   {"white_density", r.fit.white_density},
                   {"gauss_markov_sigma", r.fit.gm_sigma},
                   {"gauss_markov_tau_s", r.fit.gm_tau_s},
                   {"random_walk", r.fit.random_walk},
                   {"bias_instability", r.fit.bias_instability},
                   {"bias_instability_tau_s", r.fit.bias_instability_tau_s},
                   {"longest_tau_s", r.fit.longest_tau_s},
                   {"rms_log_error", r.fit.rms_log_error},
                   {"allan", points}});
  }
  fmt::print("{}\n", nlohmann::json{{"source", args.input.file},
                                    {"device", input.source},
                                    {"bytes", input.bytes},
                                    {"read_s", input.seconds},
                                    {"skipped_lines", input.skipped},
                                    {"axes", out}}
                         .dump());
}

void PrintNoiseText(const NoiseArgs& args, const NoiseInput& input,
                    const std::vector<AxisResult>& results) {
  const AxisResult& first = results.front();
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
  // The Allan deviation at the decades, with its 68 % interval.
  fmt::print("\nAllan deviation (68 % interval) at each decade of cluster time:\n");
  for (const auto& r : results) {
    std::string line = fmt::format("{:<5} {:<4}", r.triad, std::string(1, "xyz"[r.axis]));
    double next = 0.0;
    for (const auto& p : r.detail) {
      if (p.tau_s < next * 0.999) continue;
      line += fmt::format("  {:.3g} s: {:.3g} ({:.3g}-{:.3g})", p.tau_s, p.adev, p.ci68.low,
                          p.ci68.high);
      next = std::pow(10.0, std::floor(std::log10(p.tau_s) + 1e-9) + 1);
    }
    fmt::print("{}\n", line);
  }
  fmt::print(
      "\nUnits: N in unit/sqrt(Hz) (a mean over T s has variance N^2/(2T)); GM sigma in the unit; "
      "random walk in unit/sqrt(s); B = min Allan deviation / 0.664 (IEEE). acc m/s^2, gyr "
      "rad/s, mag Gauss. A correlation time or random walk beyond a few times the longest "
      "cluster time ({:.3g} s) is an extrapolation: record a longer rest. --json gives every "
      "point with its 68 % and 95 % intervals and the Hadamard deviation.\n",
      first.fit.longest_tau_s);
  if (!args.svg.empty()) fmt::print("plot: {}\n", args.svg);
}

int Run(const NoiseArgs& args) {
  NoiseInput input;
  if (const int code = ReadNoiseInput(args.input, &input); code != 0) return code;
  const std::vector<AxisResult> results = AnalyseTriads(input);
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
                  "text columns: time in s then x y z per triad (imu_tk's .mat files, CSV)")
      ->required();
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
  cmd->add_flag("--json", args->json, "JSON: the fit and every Allan point per axis");
  cmd->callback([args] { throw CLI::RuntimeError(Run(*args)); });
}

}  // namespace turncal::tools
