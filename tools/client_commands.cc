#include "tools/client_commands.h"

#include <fmt/format.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <map>
#include <memory>
#include <set>

#include "tools/capture_command.h"
#include "tools/client_connection.h"
#include "tools/report_command.h"

namespace turncal::tools {

namespace {

struct Common {
  std::string socket = DefaultSocketPath();
  bool json = false;
};

void AddCommon(CLI::App* cmd, Common* c) {
  cmd->add_option("--socket", c->socket, "turncald's socket ($TURNCAL_SOCKET)")
      ->capture_default_str();
  cmd->add_flag("--json", c->json, "print the daemon's JSON replies, one object a line");
}

int Fail(const std::string& command, const std::string& message) {
  fmt::print(stderr, "turncal {}: {}\n", command, message);
  return 2;
}

std::string Bar(double fraction, int width) {
  fraction = std::clamp(fraction, 0.0, 1.0);
  const int full = static_cast<int>(std::lround(fraction * width));
  return "[" + std::string(static_cast<std::size_t>(full), '#') +
         std::string(static_cast<std::size_t>(width - full), '.') + "]";
}

std::string PoseText(const nlohmann::json& p) {
  if (!p.is_object()) return "?";
  return fmt::format("phi {:.1f} gamma {:.1f} psi {:.1f}", p.value("phi_deg", 0.0),
                     p.value("gamma_deg", 0.0), p.value("psi_deg", 0.0));
}

// One request, its reply printed; 0, or 2 on an error.
int Simple(const std::string& command, const Common& c, const nlohmann::json& request,
           const std::function<void(const nlohmann::json&)>& human) {
  ClientConnection conn;
  std::string error;
  if (!conn.Connect(c.socket, &error)) return Fail(command, error);
  auto reply = conn.Request(request, &error);
  if (!reply) return Fail(command, error);
  if (reply->value("class", "") == "ERROR") {
    if (c.json) fmt::print("{}\n", reply->dump());
    return Fail(command, reply->value("message", "error"));
  }
  if (c.json) {
    fmt::print("{}\n", reply->dump());
  } else {
    human(*reply);
  }
  return 0;
}

void PrintStatus(const nlohmann::json& s) {
  fmt::print("turncald {}  up {:.0f} s  {} client(s)  {}\n", s.value("release", "?"),
             s.value("uptime_s", 0.0), s.value("clients", 0), s.value("summary", ""));
  if (const nlohmann::json& r = s.value("registry", nlohmann::json()); r.is_object()) {
    // The registry's outbox (daemon/registry_outbox.h): what waits, and why.
    auto text = [&r](const char* key) {
      return r[key].is_string() ? r[key].get<std::string>() : std::string("-");
    };
    fmt::print(
        "registry (station {}): {}  outbox {} waiting  sent {}  already there {}  "
        "rejected {}  last sent {}\n",
        text("station"), r.value("connected", false) ? "connected" : "not connected",
        r.value("depth", 0), r.value("sent", 0), r.value("already_there", 0),
        r.value("rejected", 0), text("last_sent_time"));
    if (r["last_error"].is_string()) {
      fmt::print("  last error ({}): {}\n", text("last_error_time"), text("last_error"));
    }
  }
  for (const auto& [name, d] : s["devices"].items()) {
    const auto& k = d["counters"];
    fmt::print("\n{} ({} on {}): {}  {:.1f} Hz\n", name, d.value("protocol", "?"),
               d.value("port", "?"), d.value("state", "?"), d.value("rate_hz", 0.0));
    if (!d.value("message", "").empty()) fmt::print("  {}\n", d.value("message", ""));
    fmt::print("  samples {}  frames {}  bad checksums {}  skipped bytes {}  lost {}\n",
               k.value("samples", 0), k.value("frames", 0), k.value("bad_checksums", 0),
               k.value("skipped_bytes", 0), k.value("lost_samples", 0));
    if (!d.contains("station")) continue;
    const auto& st = d["station"];
    const bool free = st.value("pose_source", "") == "free";
    if (free) {
      const auto f = st.value("free", nlohmann::json::object());
      fmt::print(
          "  free mode: intervals {}  skipped {}  noise {}{}\n", st.value("captured", 0),
          f.value("skipped", 0), st.value("noise", "?"),
          f.value("last_skip", "").empty() ? "" : "  (last skip " + f.value("last_skip", "") + ")");
    } else {
      fmt::print("  poses captured {}  rejected {}  noise {}\n", st.value("captured", 0),
                 st.value("rejected", 0), st.value("noise", "?"));
    }
    if (st["current"].is_object()) {
      const auto& cur = st["current"];
      const double needed = std::max(1.0, cur.value("needed", 1.0));
      fmt::print("  pose {} ({}): {} {}\n", cur.value("index", -1), PoseText(cur["pose"]),
                 cur.value("class", ""), Bar(cur.value("collected", 0.0) / needed, 20));
    }
    for (const auto& [model, m] : st["models"].items()) {
      const auto& g = m["gate"];
      const std::string fitted = m.value("model", model);
      fmt::print(
          "  {:8} gate {}  active v{}{}{}\n", model, g.value("pass", false) ? "PASS" : "fail",
          m.value("active_version", 0), fitted != model ? "  (fitted as " + fitted + ")" : "",
          g["reasons"].empty() ? std::string() : "  (" + g["reasons"][0].get<std::string>() + ")");
      if (free && m.contains("advice") && m["advice"].is_string()) {
        fmt::print("           next: {}\n", m["advice"].get<std::string>());
      }
    }
  }
}

void PrintResult(const nlohmann::json& r) {
  for (const auto& [name, d] : r["devices"].items()) {
    const bool free = d.value("pose_source", "") == "free";
    fmt::print("{}: {} {}\n", name, d.value("poses", 0),
               free ? "static intervals (free mode: no table)" : "poses");
    for (const auto& [model, m] : d["models"].items()) {
      const auto& g = m["gate"];
      const std::string fitted = m.value("model", model);
      fmt::print("  {}{} (rank {}, chi2 {:.1f} / {} dof): gate {}, active v{}\n", model,
                 fitted != model ? " fitted as " + fitted : "", m.value("rank", 0),
                 m.value("chi2", 0.0), m.value("dof", 0), g.value("pass", false) ? "PASS" : "fail",
                 m.value("active_version", 0));
      if (free && m.value("ok", false)) {
        fmt::print(
            "    coverage {:.1f} % of the sphere{}\n", 100 * m["coverage"].value("fraction", 0.0),
            m.value("relative_scale", false) ? "; the field's magnitude not known: relative" : "");
        if (!m.value("note", "").empty()) fmt::print("    note: {}\n", m.value("note", ""));
      }
      for (const auto& [p, v] : m["params"].items()) {
        if (v["sigma"].is_null()) {
          fmt::print("    {:14} {:>14.7g}   (undetermined)\n", p, v.value("value", 0.0));
        } else {
          fmt::print("    {:14} {:>14.7g} +- {:.3g}\n", p, v.value("value", 0.0),
                     v["sigma"].get<double>());
        }
      }
      for (const auto& reason : g["reasons"]) fmt::print("    - {}\n", reason.get<std::string>());
      if (free && m.contains("advice") && m["advice"].is_object()) {
        fmt::print("    next orientation: {}\n", m["advice"].value("text", ""));
      }
    }
  }
}

void PrintNextPose(const nlohmann::json& a) {
  if (!a.value("ok", false)) {
    fmt::print("no recommendation: {}\n", a.value("error", "?"));
    return;
  }
  if (a.value("pose_source", "") == "free") {
    fmt::print("next orientation for {} (free mode; gates {}):\n", a.value("device", "?"),
               a.value("gates_pass", false) ? "all pass" : "not all pass");
    for (const auto& m : a.value("advice", nlohmann::json::array())) {
      fmt::print("  {}: {}{}\n", m.value("model", "?"),
                 m["text"].is_string() ? m["text"].get<std::string>() : "no candidate",
                 m.value("gate_pass", false) ? "  (gate passes)" : "");
    }
    return;
  }
  fmt::print("next pose for {}: {}\n", a.value("device", "?"), PoseText(a["pose"]));
  const int to_gate = a.value("poses_to_gate", -1);
  if (to_gate >= 0) fmt::print("poses still needed for the gate: {}\n", to_gate);
}

// The live view of `turncal watch`: progress per device and the latest precision.
struct WatchView {
  struct Device {
    nlohmann::json current;  // last POSE_* progress event
    int captured = 0, rejected = 0;
    std::string last;
    std::map<std::string, nlohmann::json> estimates;  // model -> ESTIMATE
  };
  std::map<std::string, Device> devices;
  std::vector<std::string> log;

  void Take(const nlohmann::json& e) {
    const std::string kind = e.value("class", "");
    const std::string name = e.value("device", "");
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
  // events a log does not need (progress, samples, the watch confirmation).
  static std::string Describe(const nlohmann::json& e) {
    const std::string kind = e.value("class", "");
    const std::string name = e.value("device", "");
    if (kind == "POSE_PROGRESS" || kind == "WATCH" || kind == "POSE_COLLECTING") return "";
    if (kind == "POSE_STARTED") {
      return fmt::format("{}: pose {} ({}) started", name, e.value("index", -1),
                         PoseText(e.value("pose", nlohmann::json())));
    }
    if (kind == "POSE_CAPTURED" || kind == "POSE_REJECTED") {
      return fmt::format("{}: pose {} {}: {}", name, e.value("index", -1),
                         kind == "POSE_CAPTURED" ? "captured" : "REJECTED", e.value("reason", ""));
    }
    if (kind == "ESTIMATE") {
      const nlohmann::json gate = e.value("gate", nlohmann::json::object());
      std::string line =
          fmt::format("{}: {} after {} {}: gate {}", name, e.value("model", ""),
                      e.value("poses", 0), e.contains("intervals") ? "intervals" : "poses",
                      gate.value("pass", false) ? "PASS" : "fail");
      const auto reasons = gate.value("reasons", nlohmann::json::array());
      if (!reasons.empty() && reasons[0].is_string()) {
        line += " (" + reasons[0].get<std::string>();
        if (reasons.size() > 1) line += fmt::format("; {} more", reasons.size() - 1);
        line += ")";
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

  std::string Render() const {
    std::string out;
    for (const auto& [name, d] : devices) {
      out += fmt::format("{}: {} poses captured, {} rejected   {}\n", name, d.captured, d.rejected,
                         d.last);
      if (d.current.is_object()) {
        const double needed = std::max(1.0, d.current.value("needed", 1.0));
        const double collected = d.current.value("collected", 0.0);
        out += fmt::format("  pose {} ({}) {} {} {:3.0f}%\n", d.current.value("index", -1),
                           PoseText(d.current["pose"]), d.current.value("class", ""),
                           Bar(collected / needed, 30), 100 * collected / needed);
      }
      for (const auto& [model, e] : d.estimates) {
        out += fmt::format("  {} after {} {}: gate {}\n", model, e.value("poses", 0),
                           e.contains("intervals") ? "intervals" : "poses",
                           e["gate"].value("pass", false) ? "PASS" : "fail");
        if (!e.contains("precision")) continue;
        for (const auto& [p, v] : e["precision"].items()) {
          if (v["sigma"].is_null()) {
            out += fmt::format("    {:14} sigma undetermined\n", p);
            continue;
          }
          const double sigma = v["sigma"].get<double>(), tol = v.value("tolerance", 1.0);
          // The bar fills as sigma approaches the tolerance from 10x above (log scale).
          const double fill = std::clamp(1.0 - std::log10(std::max(sigma / tol, 1e-9)), 0.0, 1.0);
          out += fmt::format("    {:14} {} sigma {:.3g} / tol {:.3g}{}\n", p, Bar(fill, 20), sigma,
                             tol, sigma <= tol ? "  ok" : "");
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
      const std::string text = WatchView::Describe(e);
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

struct PoseArgs {
  Common common;
  double phi = 0, gamma = 0, psi = 0;
  std::string axis;  // a rate segment (turncal rate): outer | middle | inner
  double rate_dps = 0;
  std::string device;
  double dwell = 0;
  int index = -1;
  double timeout_s = 120;
};

int RunPose(const PoseArgs& a) {
  ClientConnection conn;
  std::string error;
  const bool rate = !a.axis.empty();
  const char* what = rate ? "rate" : "pose";
  if (!conn.Connect(a.common.socket, &error)) return Fail(what, error);
  nlohmann::json request = {
      {"cmd", what}, {"phi_deg", a.phi}, {"gamma_deg", a.gamma}, {"psi_deg", a.psi}};
  if (rate) {
    request["axis"] = a.axis;
    request["rate_dps"] = a.rate_dps;
  }
  if (!a.device.empty()) request["device"] = a.device;
  if (a.dwell > 0) request["dwell_s"] = a.dwell;
  if (a.index >= 0) request["index"] = a.index;
  if (!conn.Send(request, &error)) return Fail(what, error);
  const bool tty = !a.common.json && ::isatty(STDERR_FILENO);
  std::set<std::string> waiting;
  int index = -1;
  bool rejected = false;
  const auto deadline =
      std::chrono::steady_clock::now() + std::chrono::duration<double>(a.timeout_s);
  while (index < 0 || !waiting.empty()) {
    if (std::chrono::steady_clock::now() > deadline) {
      return Fail(what, fmt::format("no answer within {} s (--timeout)", a.timeout_s));
    }
    auto line = conn.ReadLine(std::chrono::milliseconds(200), &error);
    if (!line) {
      if (!error.empty()) return Fail(what, error);
      continue;
    }
    nlohmann::json e = nlohmann::json::parse(*line, nullptr, false);
    if (e.is_discarded()) continue;
    const std::string kind = e.value("class", "");
    if (a.common.json) fmt::print("{}\n", *line);
    if (kind == "ERROR" && !e.contains("device")) {
      return a.common.json ? 2 : Fail(what, e.value("message", ""));
    }
    if (kind == "POSE_ACCEPTED") {
      index = e.value("index", -1);
      for (const auto& d : e["devices"]) waiting.insert(d.get<std::string>());
      for (const auto& [d, state] : e["skipped"].items()) {
        fmt::print(stderr, "turncal {}: {} skipped ({})\n", what, d, state.get<std::string>());
      }
      continue;
    }
    if (e.value("index", -2) != index) continue;
    const std::string device = e.value("device", "");
    if (kind == "POSE_PROGRESS" && tty) {
      const double needed = std::max(1.0, e.value("needed", 1.0));
      fmt::print(stderr, "\r{} pose {} {}", device, index,
                 Bar(e.value("collected", 0.0) / needed, 30));
    } else if (kind == "POSE_CAPTURED" || kind == "POSE_REJECTED") {
      waiting.erase(device);
      rejected = rejected || kind == "POSE_REJECTED";
      if (!a.common.json) {
        fmt::print("{}{}: pose {} {}: {}\n", tty ? "\r" : "", device, index,
                   kind == "POSE_CAPTURED" ? "captured" : "REJECTED", e.value("reason", ""));
      }
    }
  }
  return rejected ? 1 : 0;
}

}  // namespace

void AddClientCommands(CLI::App* app) {
  auto status = std::make_shared<Common>();
  auto* s = app->add_subcommand("status", "the daemon's devices, poses and gates");
  AddCommon(s, status.get());
  s->callback([status] {
    throw CLI::RuntimeError(Simple("status", *status, {{"cmd", "status"}}, PrintStatus));
  });

  struct DevicesArgs {
    Common common;
    bool local = false;
  };
  auto devices = std::make_shared<DevicesArgs>();
  auto* d = app->add_subcommand(
      "devices", "the daemon's devices and what they said (--local: this machine's serial ports)");
  AddCommon(d, &devices->common);
  d->add_flag("--local", devices->local, "list this machine's serial ports (libserialport)");
  d->callback([devices] {
    if (devices->local) throw CLI::RuntimeError(RunLocalDevices(devices->common.json));
    throw CLI::RuntimeError(
        Simple("devices", devices->common, {{"cmd", "devices"}}, [](const auto& r) {
          for (const auto& x : r["devices"]) {
            fmt::print("{:10} {:12} {:28} {:18} {:7.1f} Hz  {}\n", x.value("name", ""),
                       x.value("protocol", ""), x.value("port", ""), x.value("state", ""),
                       x.value("rate_hz", 0.0),
                       x["identity"].is_null() ? "" : x["identity"].dump());
          }
        }));
  });

  auto result = std::make_shared<Common>();
  auto* r = app->add_subcommand("result", "current estimates with sigma, rank and gate");
  AddCommon(r, result.get());
  r->callback([result] {
    throw CLI::RuntimeError(Simple("result", *result, {{"cmd", "result"}}, PrintResult));
  });

  struct ReportArgs {
    Common common;
    HtmlReportArgs html;
  };
  auto report = std::make_shared<ReportArgs>();
  auto* rp = app->add_subcommand(
      "report",
      "status and result together (a session report); with -o or --state-dir: the HTML "
      "calibration report of each device's active calibrations");
  AddCommon(rp, &report->common);
  rp->add_option("-o,--output", report->html.output,
                 "write the HTML report here; with several devices and no --device, one file per "
                 "device with its name before the extension (report.html -> report.imu1.html)")
      ->capture_default_str();
  rp->add_option("--state-dir", report->html.state_dir,
                 "read DIR/calibrations/*.json directly (no daemon needed); without it, -o asks "
                 "the daemon for its state directory");
  rp->add_option("--device", report->html.device, "only this device's report (with -o)");
  rp->callback([report, rp] {
    const bool html =
        rp->count("--output") > 0 || rp->count("--state-dir") > 0 || rp->count("--device") > 0;
    if (html) {
      report->html.socket = report->common.socket;
      report->html.json = report->common.json;
      throw CLI::RuntimeError(RunHtmlReport(report->html));
    }
    int rc = Simple("report", report->common, {{"cmd", "status"}}, PrintStatus);
    if (rc == 0) {
      if (!report->common.json) fmt::print("\n");
      rc = Simple("report", report->common, {{"cmd", "result"}}, PrintResult);
    }
    throw CLI::RuntimeError(rc);
  });

  struct NextArgs {
    Common common;
    std::string device;
  };
  auto next = std::make_shared<NextArgs>();
  auto* n = app->add_subcommand("next-pose", "the most informative pose to capture next");
  AddCommon(n, &next->common);
  n->add_option("--device", next->device, "device (default: the first)");
  n->callback([next] {
    nlohmann::json request = {{"cmd", "next_pose"}};
    if (!next->device.empty()) request["device"] = next->device;
    throw CLI::RuntimeError(Simple("next-pose", next->common, request, PrintNextPose));
  });

  auto watch = std::make_shared<WatchArgs>();
  auto* w = app->add_subcommand(
      "watch", "live view: pose progress, poses captured, sigma against tolerance");
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

  auto pose = std::make_shared<PoseArgs>();
  auto* p = app->add_subcommand(
      "pose", "announce the table's pose (degrees) and wait until it is captured or rejected");
  AddCommon(p, &pose->common);
  p->add_option("phi", pose->phi, "inner axis, degrees")->required();
  p->add_option("gamma", pose->gamma, "middle axis, degrees")->required();
  p->add_option("psi", pose->psi, "outer axis, degrees")->required();
  p->add_option("--device", pose->device, "only this device (default: every streaming device)");
  p->add_option("--dwell", pose->dwell, "seconds to average (default: the daemon's)")
      ->check(CLI::PositiveNumber);
  p->add_option("--index", pose->index, "the pose's index (default: the next)");
  p->add_option("--timeout", pose->timeout_s, "give up after this many seconds")
      ->capture_default_str();
  p->callback([pose] { throw CLI::RuntimeError(RunPose(*pose)); });

  auto spin = std::make_shared<PoseArgs>();
  auto* rt = app->add_subcommand(
      "rate",
      "announce a rate segment: the table turns about AXIS at RATE deg/s, the other axes at "
      "--phi/--gamma/--psi; wait until the gyro's whole revolutions are captured or rejected "
      "(docs/protocol.md \"rate\")");
  AddCommon(rt, &spin->common);
  rt->add_option("axis", spin->axis, "outer | middle | inner")
      ->required()
      ->check(CLI::IsMember({"outer", "middle", "inner"}));
  rt->add_option("rate", spin->rate_dps, "deg/s, signed")->required();
  rt->add_option("--phi", spin->phi, "inner axis angle, degrees")->capture_default_str();
  rt->add_option("--gamma", spin->gamma, "middle axis angle, degrees")->capture_default_str();
  rt->add_option("--psi", spin->psi, "outer axis angle, degrees")->capture_default_str();
  rt->add_option("--device", spin->device, "only this device (default: every streaming device)");
  rt->add_option("--dwell", spin->dwell,
                 "least seconds to average, rounded up to whole revolutions (default: the "
                 "daemon's dwell)")
      ->check(CLI::PositiveNumber);
  rt->add_option("--index", spin->index, "the segment's index (default: the next)");
  rt->add_option("--timeout", spin->timeout_s, "give up after this many seconds")
      ->capture_default_str();
  rt->callback([spin] { throw CLI::RuntimeError(RunPose(*spin)); });

  struct ResetArgs {
    Common common;
    std::string note;
  };
  auto reset = std::make_shared<ResetArgs>();
  auto* rs = app->add_subcommand("reset", "start a new session (the current one is archived)");
  AddCommon(rs, &reset->common);
  rs->add_option("--note", reset->note, "why (recorded)");
  rs->callback([reset] {
    throw CLI::RuntimeError(Simple(
        "reset", reset->common, {{"cmd", "reset"}, {"note", reset->note}}, [](const auto& x) {
          fmt::print("new session; previous one archived in {}\n",
                     x["archived"].is_null() ? std::string("(nothing to archive)")
                                             : x["archived"].template get<std::string>());
        }));
  });

  struct PublishArgs {
    Common common;
    std::string device, model, operator_name, reason;
  };
  auto publish = std::make_shared<PublishArgs>();
  auto* pb = app->add_subcommand(
      "publish", "operator override: make an estimate active although its gate failed");
  AddCommon(pb, &publish->common);
  pb->add_option("device", publish->device, "device")->required();
  pb->add_option("model", publish->model, "model, e.g. accel13")->required();
  pb->add_option("--operator", publish->operator_name, "who decides (recorded)")->required();
  pb->add_option("--reason", publish->reason, "why (recorded)")->required();
  pb->callback([publish] {
    throw CLI::RuntimeError(Simple("publish", publish->common,
                                   {{"cmd", "publish"},
                                    {"override", true},
                                    {"device", publish->device},
                                    {"model", publish->model},
                                    {"operator", publish->operator_name},
                                    {"reason", publish->reason}},
                                   [](const auto& x) {
                                     fmt::print("{} {} published by operator override\n",
                                                x.value("device", ""), x.value("model", ""));
                                   }));
  });
}

}  // namespace turncal::tools
