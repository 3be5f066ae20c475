#include "tools/noise_command.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <memory>
#include <nlohmann/json.hpp>
#include <sstream>

#include "core/analysis/allan.h"
#include "daemon/state/atomic_file.h"
#include "daemon/station/capture_replay.h"
#include "drivers/capture/tcap.h"
#include "drivers/decoder_factory.h"
#include "tools/help_text.h"

namespace turncal::tools {

namespace {

struct NoiseArgs {
  std::string file;
  std::string protocol;    // raw streams
  std::string text_triad;  // text columns: acc | gyr | mag
  double text_scale = 1.0;
  std::string device;
  double from_s = 0.0;
  double to_s = INFINITY;
  std::string svg;
  bool json = false;
};

// The samples of one device, in time order.
struct Series {
  std::vector<double> t_s;
  std::vector<Eigen::Vector3d> acc, gyr, mag;
  std::vector<double> t_acc, t_gyr, t_mag;
};

void AddSample(const Sample& s, double t, Series* out) {
  out->t_s.push_back(t);
  if (s.acc_mps2) out->acc.push_back(*s.acc_mps2), out->t_acc.push_back(t);
  if (s.gyr_radps) out->gyr.push_back(*s.gyr_radps), out->t_gyr.push_back(t);
  if (s.mag) out->mag.push_back(*s.mag), out->t_mag.push_back(t);
}

double SampleTime(const Sample& s) {
  return s.t_device_s ? *s.t_device_s : static_cast<double>(s.t_host_ns) * 1e-9;
}

class Collector : public daemon::ReplayTarget, public drivers::DecoderSink {
 public:
  explicit Collector(int device) : device_(device) {}
  void OnSample(int device, const Sample& s) override {
    if (device == device_) AddSample(s, SampleTime(s), &series);
  }
  bool OnAnnounce(const Announcement&, const std::vector<int>&, std::string*) override {
    return true;
  }
  void OnTick(std::int64_t) override {}
  void OnFinish(std::int64_t) override {}
  void OnFrame(const drivers::FrameView&) override {}
  void OnSample(const Sample& s) override { AddSample(s, SampleTime(s), &series); }
  Series series;

 private:
  int device_;
};

// Text columns: time in seconds, then x y z (imu_tk's .mat text files, CSV exports); lines that
// do not parse (headers, comments) are skipped and counted.
bool ReadText(const NoiseArgs& args, Series* out, int* skipped, std::string* error) {
  std::ifstream in(args.file);
  if (!in) {
    *error = "cannot open '" + args.file + "'";
    return false;
  }
  std::string line;
  while (std::getline(in, line)) {
    std::replace(line.begin(), line.end(), ',', ' ');
    std::istringstream ls(line);
    double t, x, y, z;
    if (!(ls >> t >> x >> y >> z) || !std::isfinite(t + x + y + z)) {
      ++*skipped;
      continue;
    }
    Sample s;
    const Eigen::Vector3d v = args.text_scale * Eigen::Vector3d(x, y, z);
    if (args.text_triad == "gyr") {
      s.gyr_radps = v;
    } else if (args.text_triad == "mag") {
      s.mag = v;
    } else {
      s.acc_mps2 = v;
    }
    AddSample(s, t, out);
  }
  return true;
}

struct AxisResult {
  std::string triad;
  int axis = 0;
  std::vector<AllanPoint> points;
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
      for (const auto& p : r.points) {
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
      for (const auto& p : r.points) {
        o += fmt::format("<circle cx=\"{:.1f}\" cy=\"{:.1f}\" r=\"2\" fill=\"{}\"/>\n", X(p.tau_s),
                         Y(p.adev), c);
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
    "The overlapping Allan deviation of a static recording, per triad and axis, and the noise "
    "model fitted to it: white-noise density N, a Gauss-Markov bias instability (sigma, tau), "
    "a random walk, and the IEEE flat-bottom figure. Record the sensor at rest for several "
    "times the longest correlation time you care about; use --from/--to to keep only the "
    "rest. The fitted values go into turncald.toml's [station] as the noise prior: "
    "acc_noise_density, acc_bias_instability (GM sigma), bias_tau_s (GM tau), acc_random_walk "
    "and the mag_ equivalents (docs/ACCURACY.md \"Drift\").",
    "turncal noise rest.tcap --svg rest-allan.svg\n"
    "turncal noise imu.bin --protocol mip --to 600 --json\n"
    "turncal noise xsens_acc.mat --triad acc --to 45   # imu_tk's text columns (raw counts)",
    "0 done; 1 no triad with enough samples, or the plot cannot be written; 2 the input "
    "cannot be read or a command-line mistake",
    "docs/ACCURACY.md (the noise model), SENSORS.md"};

// A capture's device (--device, or the first) as a series; `source` its name. 0, or the code to
// return.
int ReadCaptureSeries(const NoiseArgs& args, Series* series, std::string* source) {
  std::string error;
  drivers::CaptureReader reader;
  if (!reader.Open(args.file, &error)) {
    fmt::print(stderr, "turncal noise: {}\n", error);
    return 2;
  }
  int device = 0;
  if (!args.device.empty()) {
    device = -1;
    for (std::size_t i = 0; i < reader.header().devices.size(); ++i)
      if (reader.header().devices[i].name == args.device) device = static_cast<int>(i);
    if (device < 0) {
      fmt::print(stderr, "turncal noise: the capture has no device '{}'\n", args.device);
      return 2;
    }
  }
  *source = reader.header().devices.empty()
                ? ""
                : reader.header().devices[static_cast<std::size_t>(device)].name;
  Collector collector(device);
  daemon::ReplayStats stats;
  if (!daemon::ReplayInto(&reader, &collector, false, {}, &stats, &error)) {
    fmt::print(stderr, "turncal noise: {}\n", error);
    return 2;
  }
  *series = std::move(collector.series);
  return 0;
}

// A raw device stream in --protocol as a series. 0, or the code to return.
int DecodeRawSeries(const NoiseArgs& args, Series* series) {
  std::string error;
  const auto protocol = drivers::ParseProtocol(args.protocol);
  if (!protocol) {
    fmt::print(stderr, "turncal noise: unknown protocol '{}'\n", args.protocol);
    return 2;
  }
  Collector collector(0);
  auto decoder = drivers::MakeDecoder(*protocol, drivers::DecoderOptions{}, &collector, &error);
  if (!decoder) {
    fmt::print(stderr, "turncal noise: {}\n", error);
    return 2;
  }
  std::ifstream in(args.file, std::ios::binary);
  drivers::DecodeStream(in, decoder.get());
  *series = std::move(collector.series);
  return 0;
}

// The file as a series, whichever kind it is (a capture, a raw stream, text columns); `skipped`
// the text lines passed over, `source` the capture's device. 0, or the code to return.
int ReadSeries(const NoiseArgs& args, Series* series, int* skipped, std::string* source) {
  const std::optional<bool> is_capture = drivers::FileLooksLikeCapture(args.file);
  if (!is_capture) {
    fmt::print(stderr, "turncal noise: cannot open '{}'\n", args.file);
    return 2;
  }
  if (*is_capture) return ReadCaptureSeries(args, series, source);
  if (!args.protocol.empty()) return DecodeRawSeries(args, series);
  std::string error;
  if (!ReadText(args, series, skipped, &error)) {
    fmt::print(stderr, "turncal noise: {}\n", error);
    return 2;
  }
  return 0;
}

// The Allan deviation and noise fit of every axis of every triad with at least 16 intervals in
// [from, to] (the median interval as the sample period).
std::vector<AxisResult> AnalyseTriads(const NoiseArgs& args, const Series& series) {
  std::vector<AxisResult> results;
  const std::pair<const char*,
                  std::pair<const std::vector<Eigen::Vector3d>*, const std::vector<double>*>>
      triads[] = {{"acc", {&series.acc, &series.t_acc}},
                  {"gyr", {&series.gyr, &series.t_gyr}},
                  {"mag", {&series.mag, &series.t_mag}}};
  for (const auto& [name, data] : triads) {
    const auto& values = *data.first;
    const auto& times = *data.second;
    if (values.empty()) continue;
    const double t0 = times.front();
    std::vector<double> dts;
    std::vector<std::size_t> keep;
    for (std::size_t i = 0; i < values.size(); ++i) {
      const double t = times[i] - t0;
      if (t >= args.from_s && t <= args.to_s) keep.push_back(i);
    }
    for (std::size_t j = 1; j < keep.size(); ++j)
      dts.push_back(times[keep[j]] - times[keep[j - 1]]);
    if (dts.size() < 16) continue;
    std::nth_element(dts.begin(), dts.begin() + static_cast<long>(dts.size() / 2), dts.end());
    const double dt = dts[dts.size() / 2];
    if (!(dt > 0)) continue;
    for (int axis = 0; axis < 3; ++axis) {
      std::vector<double> x;
      for (std::size_t i : keep) x.push_back(values[i][axis]);
      AxisResult r;
      r.triad = name;
      r.axis = axis;
      r.points = OverlappingAllan(x, dt);
      r.fit = FitNoiseModel(r.points);
      r.samples = x.size();
      r.rate_hz = 1.0 / dt;
      results.push_back(std::move(r));
    }
  }
  return results;
}

void PrintNoiseJson(const NoiseArgs& args, const std::string& source,
                    const std::vector<AxisResult>& results) {
  nlohmann::json out = nlohmann::json::array();
  for (const auto& r : results) {
    nlohmann::json points = nlohmann::json::array();
    for (const auto& p : r.points) points.push_back({p.tau_s, p.adev});
    out.push_back({{"triad", r.triad},
                   {"axis", std::string(1, "xyz"[r.axis])},
                   {"unit", Unit(r.triad)},
                   {"samples", r.samples},
                   {"rate_hz", r.rate_hz},
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
  fmt::print("{}\n",
             nlohmann::json{{"source", args.file}, {"device", source}, {"axes", out}}.dump());
}

void PrintNoiseText(const NoiseArgs& args, const std::string& source, int skipped,
                    const std::vector<AxisResult>& results) {
  fmt::print("{}{}: {} samples at {:.4g} Hz ({:.1f} s){}\n", args.file,
             source.empty() ? "" : " (" + source + ")", results.front().samples,
             results.front().rate_hz,
             static_cast<double>(results.front().samples) / results.front().rate_hz,
             skipped ? fmt::format(", {} lines skipped", skipped) : "");
  fmt::print("\n{:<5} {:<4} {:>13} {:>13} {:>10} {:>13} {:>13} {:>10} {:>8}\n", "triad", "axis",
             "white N", "GM sigma", "GM tau s", "random walk", "flat bottom B", "at tau s",
             "fit err");
  for (const auto& r : results) {
    fmt::print("{:<5} {:<4} {:>13.4g} {:>13.4g} {:>10.4g} {:>13.4g} {:>13.4g} {:>10.3g} {:>8.3f}\n",
               r.triad, std::string(1, "xyz"[r.axis]), r.fit.white_density, r.fit.gm_sigma,
               r.fit.gm_tau_s, r.fit.random_walk, r.fit.bias_instability,
               r.fit.bias_instability_tau_s, r.fit.rms_log_error);
  }
  fmt::print(
      "\nUnits: N in unit/sqrt(Hz) (a mean over T s has variance N^2/(2T)); GM sigma in the unit; "
      "random walk in unit/sqrt(s); B = min Allan deviation / 0.664 (IEEE). acc m/s^2, gyr "
      "rad/s, mag Gauss. A correlation time or random walk beyond a few times the longest "
      "cluster time ({:.3g} s) is an extrapolation: record a longer rest.\n",
      results.front().fit.longest_tau_s);
  if (!args.svg.empty()) fmt::print("plot: {}\n", args.svg);
}

int Run(const NoiseArgs& args) {
  Series series;
  int skipped = 0;
  std::string source;
  if (const int code = ReadSeries(args, &series, &skipped, &source); code != 0) return code;
  const std::vector<AxisResult> results = AnalyseTriads(args, series);
  if (results.empty()) {
    fmt::print(stderr, "turncal noise: '{}' has no triad with enough samples in the window\n",
               args.file);
    return 1;
  }
  std::string error;
  if (!args.svg.empty() && !daemon::WriteFileAtomically(args.svg, Svg(results), &error)) {
    fmt::print(stderr, "turncal noise: {}\n", error);
    return 1;
  }
  if (args.json) {
    PrintNoiseJson(args, source, results);
  } else {
    PrintNoiseText(args, source, skipped, results);
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
  cmd->add_option("file", args->file,
                  "a .tcap capture, a raw device stream (with --protocol), or text columns: time "
                  "in s then x y z (imu_tk's .mat files, CSV)")
      ->required();
  cmd->add_option("--protocol", args->protocol, "raw streams: mip | gx2 | xbus | xbus-legacy");
  cmd->add_option("--triad", args->text_triad, "text columns: acc | gyr | mag")
      ->check(CLI::IsMember({"acc", "gyr", "mag"}))
      ->default_val("acc");
  cmd->add_option("--scale", args->text_scale,
                  "text columns: multiply the values by this (e.g. counts to m/s^2)")
      ->capture_default_str();
  cmd->add_option("--device", args->device, "captures: the device (default: the first)");
  cmd->add_option("--from", args->from_s, "seconds from the first sample to start at")
      ->check(CLI::NonNegativeNumber);
  cmd->add_option("--to", args->to_s, "seconds from the first sample to stop at (the rest only)")
      ->check(CLI::PositiveNumber);
  cmd->add_option("--svg", args->svg, "write the log-log plot with the fitted lines here");
  cmd->add_flag("--json", args->json, "JSON: the fit and every Allan point per axis");
  cmd->callback([args] { throw CLI::RuntimeError(Run(*args)); });
}

}  // namespace turncal::tools
