#include "tools/watch_command.h"

#include <fmt/format.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <map>
#include <memory>
#include <vector>

#include "tools/client_common.h"
#include "tools/help_text.h"

namespace turncal::tools {
namespace {

// The codes RunWatch returns.
constexpr Manual kWatchManual = {
    "Live view: pose progress, poses captured, each parameter's sigma against its tolerance; in "
    "free mode the magnetometer's coverage of the sphere filling, the largest region without a "
    "value and how to turn into it, each fit's error and the orientation to add. "
    "On a terminal the view redraws in place; otherwise one line per event (a log). With "
    "--corrected / --raw it also prints samples; --json prints the daemon's messages "
    "unchanged. {socket}",
    "turncal watch\n"
    "turncal watch --corrected --rate 10 --json     # corrected samples for a script\n"
    "turncal watch --seconds 60 > session.log",
    "0 after --count samples or --seconds; 2 the daemon cannot be reached, an error, or the "
    "daemon closed the connection",
    "docs/protocol.md (watch, CORRECTED)"};

// The live view of `turncal watch`: progress per device and the latest precision.
struct WatchView {
  struct Device {
    nlohmann::json current;  // last POSE_* progress event
    int captured = 0, rejected = 0;
    std::string last;
    std::map<std::string, nlohmann::json> estimates;  // model -> ESTIMATE
    nlohmann::json coverage;                          // the latest COVERAGE (free mode)
    int coverage_logged = -1;                         // the tenth of the sphere last logged
  };
  std::map<std::string, Device> devices;
  std::vector<std::string> log;
  nlohmann::json batch;  // the latest BATCH: the fixture slot by slot

  void Take(const nlohmann::json& e) {
    const std::string kind = e.value("class", "");
    const std::string name = e.value("device", "");
    if (kind == "BATCH") {
      batch = e;
      return;
    }
    if (name.empty()) {
      if (kind != "WATCH") log.push_back(e.dump().substr(0, 160));
      return;
    }
    Device& d = devices[name];
    if (kind == "POSE_STARTED" || kind == "POSE_COLLECTING" || kind == "POSE_PROGRESS") {
      d.current = e;
    } else if (kind == "POSE_CAPTURED") {
      ++d.captured;
      d.current = nlohmann::json();
      d.last = fmt::format("pose {} captured ({})", e.value("index", -1), e.value("reason", ""));
    } else if (kind == "POSE_REJECTED") {
      ++d.rejected;
      d.current = nlohmann::json();
      d.last = fmt::format("pose {} REJECTED: {}", e.value("index", -1), e.value("reason", ""));
    } else if (kind == "ESTIMATE") {
      d.estimates[e.value("model", "")] = e;
    } else if (kind == "COVERAGE") {
      d.coverage = e;
    } else if (kind == "CALIBRATION_ACTIVE") {
      log.push_back(fmt::format("{} {} calibration v{} active", name, e.value("model", ""),
                                e.value("version", 0)));
    } else if (kind == "DEVICE" || kind == "ERROR" || kind.rfind("NOISE", 0) == 0) {
      log.push_back(
          fmt::format("{}: {} {}", name, kind == "DEVICE" ? e.value("state", "") : kind,
                      e.value(kind == "DEVICE" ? "message" : "reason", e.value("message", "")))
              .substr(0, 160));
    }
    if (log.size() > 6) log.erase(log.begin(), log.end() - 6);
  }

  // One line for a log (standard output not a terminal): what happened, in words; empty for the
  // events a log does not need (progress, samples, the watch confirmation, a coverage that has
  // not filled another tenth of the sphere). After Take(e).
  std::string Describe(const nlohmann::json& e) {
    const std::string kind = e.value("class", "");
    const std::string name = e.value("device", "");
    if (kind == "POSE_PROGRESS" || kind == "WATCH" || kind == "POSE_COLLECTING") return "";
    if (kind == "BATCH") {
      // The table once per change; its heading alone for a batch of one.
      const std::string table = BatchText(e);
      return !table.empty()
                 ? table.substr(0, table.size() - 1)
                 : fmt::format("batch {}: {} passed, {} waiting, {} held", e.value("id", ""),
                               e.value("passed", 0), e.value("waiting", 0), e.value("held", 0));
    }
    if (kind == "COVERAGE") {
      Device& d = devices[name];
      const int tenth = static_cast<int>(std::floor(10 * e.value("fraction", 0.0)));
      if (tenth == d.coverage_logged) return "";
      d.coverage_logged = tenth;
      std::string line = fmt::format("{}: {}", name, CoverageLine(e));
      if (e.contains("gap")) line += "; " + e["gap"].value("text", "");
      return line;
    }
    if (kind == "POSE_STARTED") {
      return fmt::format("{}: pose {} ({}) started", name, e.value("index", -1),
                         PoseJsonText(e.value("pose", nlohmann::json())));
    }
    if (kind == "POSE_CAPTURED" || kind == "POSE_REJECTED") {
      return fmt::format("{}: pose {} {}: {}", name, e.value("index", -1),
                         kind == "POSE_CAPTURED" ? "captured" : "REJECTED", e.value("reason", ""));
    }
    if (kind == "ESTIMATE") {
      const nlohmann::json gate = e.value("gate", nlohmann::json::object());
      std::string line = fmt::format("{}: {} after {}: gate {}", name, e.value("model", ""),
                                     WhatWasFitted(e), gate.value("pass", false) ? "PASS" : "fail");
      const auto reasons = gate.value("reasons", nlohmann::json::array());
      if (!reasons.empty() && reasons[0].is_string()) {
        line += " (" + reasons[0].get<std::string>();
        if (reasons.size() > 1) line += fmt::format("; {} more", reasons.size() - 1);
        line += ")";
      }
      if (e.contains("fit_error_percent")) {
        line += fmt::format("; fit error {:.2f} %", e.value("fit_error_percent", 0.0));
      }
      if (!gate.value("pass", false) && e.contains("advice")) {
        line += "; next: " + e.value("advice", "");
      }
      return line;
    }
    if (kind == "CALIBRATION_ACTIVE") {
      return fmt::format("{}: {} calibration v{} active ({} poses)", name, e.value("model", ""),
                         e.value("version", 0), e.value("poses", 0));
    }
    if (kind.rfind("NOISE", 0) == 0 || kind == "DEVICE" || kind == "ERROR") {
      std::string what = kind == "DEVICE" ? e.value("state", "") : kind;
      std::transform(what.begin(), what.end(), what.begin(),
                     [](unsigned char ch) { return ch == '_' ? ' ' : std::tolower(ch); });
      std::string line = fmt::format("{}: {}: {}", name.empty() ? "turncald" : name, what,
                                     e.value("reason", e.value("message", "")));
      if (line.size() > 200) line = line.substr(0, 197) + "...";
      return line;
    }
    nlohmann::json brief = e;
    brief.erase("record");
    return brief.dump().substr(0, 300);
  }

  // What an ESTIMATE fitted: "12 poses", "3 intervals", "0 intervals and 600 values in motion".
  static std::string WhatWasFitted(const nlohmann::json& e) {
    const int poses = e.value("poses", 0), motion = e.value("motion_points", 0);
    if (!e.contains("intervals")) return fmt::format("{} poses", poses);
    if (motion <= 0) return fmt::format("{} intervals", poses);
    return fmt::format("{} intervals and {} values in motion", poses - motion, motion);
  }

  // "magnetometer coverage 34.2 % (197 of 576 bins) from 1200 values".
  static std::string CoverageLine(const nlohmann::json& e) {
    return fmt::format("{} coverage {:.1f} % ({} of {} bins) from {} values",
                       e.value("triad", "magnetometer"), 100 * e.value("fraction", 0.0),
                       e.value("filled", 0), e.value("total", 576), e.value("values", 0));
  }

  // The coverage's 18 latitude rows drawn two to a line (half blocks), +z's pole at the top.
  static std::string CoverageMap(const nlohmann::json& e) {
    const auto rows = e.value("rows", std::vector<std::string>());
    std::string out;
    for (std::size_t r = 0; r + 1 < rows.size(); r += 2) {
      out += fmt::format("    {:>4} ", r == 0 ? "+z" : (r + 2 >= rows.size() ? "-z" : ""));
      for (std::size_t c = 0; c < rows[r].size() && c < rows[r + 1].size(); ++c) {
        const bool upper = rows[r][c] == '#', lower = rows[r + 1][c] == '#';
        out += upper && lower ? "\u2588" : upper ? "\u2580" : lower ? "\u2584" : "\u00b7";
      }
      out += "\n";
    }
    out += "         -x      -y      +x      +y      (longitude about z from -x)\n";
    return out;
  }

  std::string Render() const {
    std::string out = BatchText(batch);
    for (const auto& [name, d] : devices) {
      out += fmt::format("{}: {} poses captured, {} rejected   {}\n", name, d.captured, d.rejected,
                         d.last);
      if (d.current.is_object()) {
        const double needed = std::max(1.0, d.current.value("needed", 1.0));
        const double collected = d.current.value("collected", 0.0);
        out += fmt::format("  pose {} ({}) {} {} {:3.0f}%\n", d.current.value("index", -1),
                           PoseJsonText(d.current["pose"]), d.current.value("class", ""),
                           ProgressBar(collected / needed, 30), 100 * collected / needed);
      }
      if (d.coverage.is_object()) {
        out += "  " + CoverageLine(d.coverage) + ", centred by " + d.coverage.value("centre", "") +
               "\n";
        out += CoverageMap(d.coverage);
        if (d.coverage.contains("gap"))
          out += "  next: " + d.coverage["gap"].value("text", "") + "\n";
      }
      for (const auto& [model, e] : d.estimates) {
        const bool pass = e["gate"].value("pass", false);
        out += fmt::format(
            "  {} after {}: gate {}{}\n", model, WhatWasFitted(e), pass ? "PASS" : "fail",
            e.contains("fit_error_percent")
                ? fmt::format(", fit error {:.2f} %", e.value("fit_error_percent", 0.0))
                : std::string());
        const auto reasons = e["gate"].value("reasons", nlohmann::json::array());
        if (!pass && !reasons.empty() && reasons[0].is_string()) {
          out += "    refused: " + reasons[0].get<std::string>() + "\n";
        }
        if (!pass && e.contains("advice")) out += "    next: " + e.value("advice", "") + "\n";
        if (!e.contains("precision")) continue;
        for (const auto& [p, v] : e["precision"].items()) {
          if (v["sigma"].is_null()) {
            out += fmt::format("    {:14} sigma undetermined\n", p);
            continue;
          }
          const double sigma = v["sigma"].get<double>(), tol = v.value("tolerance", 1.0);
          // The bar fills as sigma approaches the tolerance from 10x above (log scale).
          const double fill = std::clamp(1.0 - std::log10(std::max(sigma / tol, 1e-9)), 0.0, 1.0);
          out += fmt::format("    {:14} {} sigma {:.3g} / tol {:.3g}{}\n", p, ProgressBar(fill, 20),
                             sigma, tol, sigma <= tol ? "  ok" : "");
        }
      }
    }
    for (const auto& l : log) out += l + "\n";
    return out;
  }
};

struct WatchArgs {
  Common common;
  std::string device;
  bool corrected = false, raw = false, no_events = false, uncertainty = false;
  double rate = 0.0;
  long count = 0;
  double seconds = 0.0;
};

int RunWatch(const WatchArgs& a) {
  ClientConnection conn;
  std::string error;
  if (!conn.Connect(a.common.socket, &error)) return Fail("watch", error);
  nlohmann::json request = {
      {"cmd", "watch"}, {"events", !a.no_events},       {"corrected", a.corrected},
      {"raw", a.raw},   {"uncertainty", a.uncertainty}, {"max_rate_hz", a.rate}};
  if (!a.device.empty()) request["device"] = a.device;
  auto reply = conn.Request(request, &error);
  if (!reply) return Fail("watch", error);
  if (reply->value("class", "") == "ERROR") return Fail("watch", reply->value("message", ""));
  const bool tty = !a.common.json && ::isatty(STDOUT_FILENO);
  if (a.common.json) fmt::print("{}\n", reply->dump());
  WatchView view;
  long samples = 0;
  const auto start = std::chrono::steady_clock::now();
  auto last_draw = start - std::chrono::seconds(1);
  for (;;) {
    if (a.seconds > 0 &&
        std::chrono::steady_clock::now() - start > std::chrono::duration<double>(a.seconds)) {
      return 0;
    }
    auto line = conn.ReadLine(std::chrono::milliseconds(200), &error);
    if (!line) {
      if (!error.empty()) return Fail("watch", error);
      continue;
    }
    if (a.common.json) {
      fmt::print("{}\n", *line);
      std::fflush(stdout);
    }
    const bool sample = line->rfind("{\"class\":\"CORRECTED\"", 0) == 0 ||
                        line->rfind("{\"class\":\"SAMPLE\"", 0) == 0;
    if (sample && a.count > 0 && ++samples >= a.count) return 0;
    if (a.common.json) continue;
    nlohmann::json e = nlohmann::json::parse(*line, nullptr, false);
    if (e.is_discarded()) continue;
    if (sample) {
      if (!tty) fmt::print("{}\n", *line);
      continue;
    }
    view.Take(e);
    if (!tty) {
      const std::string text = view.Describe(e);
      if (!text.empty()) fmt::print("{}\n", text);
      std::fflush(stdout);
      continue;
    }
    const auto now = std::chrono::steady_clock::now();
    if (now - last_draw > std::chrono::milliseconds(100)) {
      fmt::print("\033[H\033[J{}", view.Render());
      std::fflush(stdout);
      last_draw = now;
    }
  }
}

}  // namespace

void AddWatchCommand(CLI::App* app) {
  auto watch = std::make_shared<WatchArgs>();
  auto* w = app->add_subcommand(
      "watch", "live view: pose progress, poses captured, sigma against tolerance");
  SetManual(w, kWatchManual);
  AddCommon(w, &watch->common);
  w->add_option("--device", watch->device, "only this device");
  w->add_flag("--corrected", watch->corrected, "corrected samples too");
  w->add_flag("--raw", watch->raw, "raw samples too (alongside corrected ones with --corrected)");
  w->add_flag("--no-events", watch->no_events, "samples only");
  w->add_flag("--uncertainty", watch->uncertainty,
              "corrected samples carry the calibration's 1 sigma per axis (acc_sigma, mag_sigma)");
  w->add_option("--rate", watch->rate, "at most this many samples per second per device (0: all)")
      ->check(CLI::NonNegativeNumber);
  w->add_option("--count", watch->count, "exit after this many samples");
  w->add_option("--seconds", watch->seconds, "exit after this long");
  w->callback([watch] { throw CLI::RuntimeError(RunWatch(*watch)); });
}

}  // namespace turncal::tools
