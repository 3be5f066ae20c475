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
#include "tools/client_common.h"
#include "tools/client_connection.h"
#include "tools/help_text.h"
#include "tools/pose_command.h"
#include "tools/report_command.h"
#include "tools/watch_command.h"

namespace turncal::tools {

namespace {

void PrintStatus(const nlohmann::json& s) {
  fmt::print("turncald {}  up {:.0f} s  {} client(s)  {}\n", s.value("release", "?"),
             s.value("uptime_s", 0.0), s.value("clients", 0), s.value("summary", ""));
  if (const nlohmann::json& r = s.value("registry", nlohmann::json()); r.is_object()) {
    // The registry's outbox (daemon/registry/registry_outbox.h): what waits, and why.
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
  if (const std::string batch = BatchText(s.value("batch", nlohmann::json())); !batch.empty()) {
    fmt::print("{}", batch);
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
      fmt::print("  pose {} ({}): {} {}\n", cur.value("index", -1), PoseJsonText(cur["pose"]),
                 cur.value("class", ""), ProgressBar(cur.value("collected", 0.0) / needed, 20));
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

// A batch's units, one line each (issue 38).
void PrintBatchUnits(const nlohmann::json& batch) {
  for (const auto& u : batch.value("units", nlohmann::json::array())) {
    fmt::print("  {:<12} slot {:<6} {:>3} poses  {}\n", u.value("device", "?"),
               u["slot"].is_string() ? u["slot"].get<std::string>() : "-", u.value("poses", 0),
               u.value("state", "?"));
  }
}

void PrintNextPose(const nlohmann::json& a) {
  if (!a.value("ok", false)) {
    fmt::print("no recommendation: {}\n", a.value("error", "?"));
    if (a.contains("batch")) PrintBatchUnits(a["batch"]);
    return;
  }
  if (a.contains("batch")) {
    fmt::print("next pose for the batch ({} of {} units planned): {}\n",
               a["batch"].value("planned", 0), a["batch"]["units"].size(), PoseJsonText(a["pose"]));
    const int to_gate = a.value("poses_to_gate", -1);
    if (to_gate >= 0) {
      fmt::print("poses to the last unit's gate: {} ({:.0f} s of table time)\n", to_gate,
                 a.value("seconds_to_gate", 0.0));
    }
    PrintBatchUnits(a["batch"]);
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
  fmt::print("next pose for {}: {}\n", a.value("device", "?"), PoseJsonText(a["pose"]));
  const int to_gate = a.value("poses_to_gate", -1);
  if (to_gate >= 0) fmt::print("poses still needed for the gate: {}\n", to_gate);
}

// `turncal status`.
constexpr Manual kStatusManual = {
    "The daemon's state: every device's connection, rates and counters, poses captured, the "
    "pose being collected, each model's gate and active calibration version. {socket}",
    "turncal status\n"
    "turncal status --json | jq '.devices.imu1.counters'",
    kClientExitStatus, "docs/protocol.md (status), docs/TROUBLESHOOTING.md"};

// `turncal devices`.
constexpr Manual kDevicesManual = {
    "The daemon's devices and what they said in their configuration dialogue (identity, "
    "firmware, rate). With --local: this machine's serial ports, no daemon needed. {socket}",
    "turncal devices\n"
    "turncal devices --local          # which /dev/ttyUSB* is which IMU",
    "0 done; 2 the daemon cannot be reached (is turncald running? --socket, $TURNCAL_SOCKET), it "
    "answered ERROR, --local: this machine's serial ports cannot be listed, or a command-line "
    "mistake",
    "docs/TROUBLESHOOTING.md (permissions, ModemManager)"};

// `turncal result`.
constexpr Manual kResultManual = {
    "The current estimate of every model of every device: each parameter with its 1 sigma, "
    "rank, chi^2 and the publish gate's verdict with its reasons. {socket}",
    "turncal result\n"
    "turncal result --json > result.json   # the shape of turncald --result-out",
    kClientExitStatus, "docs/models.md (what each parameter means), docs/OBSERVABILITY.md"};

// `turncal report`.
constexpr Manual kReportManual = {
    "Without -o: status and result together, as text. With -o FILE: the calibration report, "
    "one self-contained HTML file per device (parameter table with 1 sigma and tolerances, "
    "residual, coverage and convergence plots, observability). It reads the active "
    "calibrations from the state directory (--state-dir, else the one the daemon reports). "
    "{socket}",
    "turncal report\n"
    "turncal report -o report.html\n"
    "turncal report --state-dir /var/lib/turncal --device imu1 -o imu1.html   # no daemon",
    "0 done; 2 the daemon cannot be reached, it answered ERROR, no active calibration was "
    "found, a calibration file is unreadable or malformed, --device names no device there, "
    "or a command-line mistake",
    "README.md (the walk-through), docs/models.md; turncald writes "
    "STATE_DIR/reports/DEVICE.html itself after each activation"};

// `turncal next-pose`.
constexpr Manual kNextPoseManual = {
    "The most informative pose to capture next for a device (D-optimal over its models), and "
    "how many poses the gate still needs. {socket}",
    "turncal next-pose\n"
    "turncal next-pose --device imu2 --json\n"
    "turncal next-pose --batch       # the whole fixture, to the last unit's gate",
    "0, also when there is no recommendation (printed as \"no recommendation: ...\"); 2 as "
    "for every client command: the daemon cannot be reached, it answered ERROR, or a "
    "command-line mistake",
    "docs/OBSERVABILITY.md (planning), tools/examples/turntable_controller.py --plan"};

// `turncal reset`.
constexpr Manual kResetManual = {
    "Starts a new session: the current poses and noise profiles are archived under "
    "sessions/ in the state directory; active calibrations stay active. Needs a permitted "
    "uid. {socket}",
    "turncal reset --note \"new fixture\"", kClientExitStatus,
    "systemd/README.md (state directory)"};

// `turncal publish`.
constexpr Manual kPublishManual = {
    "Operator override: makes the current estimate of DEVICE MODEL active although the gate "
    "refused it. The operator, the reason and the gate's reasons are recorded in the "
    "calibration. Needs a permitted uid. {socket}",
    "turncal publish imu1 accel13 --operator \"A. Engineer\" --reason \"re-issue after audit\"",
    kClientExitStatus, "docs/protocol.md (publish)"};

}  // namespace

void AddClientCommands(CLI::App* app) {
  auto status = std::make_shared<Common>();
  auto* s = app->add_subcommand("status", "the daemon's devices, poses and gates");
  SetManual(s, kStatusManual);
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
  SetManual(d, kDevicesManual);
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
  SetManual(r, kResultManual);
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
  SetManual(rp, kReportManual);
  AddCommon(rp, &report->common);
  rp->add_option("-o,--output", report->html.output,
                 "write the HTML report here; with several devices and no --device, one file per "
                 "device with its name before the extension (report.html -> report.imu1.html)")
      ->capture_default_str();
  rp->add_option("--state-dir", report->html.state_dir,
                 "read DIR/calibrations/*.json directly (no daemon needed); without it, -o asks "
                 "the daemon for its state directory");
  rp->add_option("--device", report->html.device, "only this device's report (with -o)");
  rp->add_option("--drift", report->html.drift,
                 "with -o: the unit's drift over its calibrations, a file of `turncal registry "
                 "drift SERIAL --json`: each model's section ends with its table");
  rp->callback([report, rp] {
    const bool html = rp->count("--output") > 0 || rp->count("--state-dir") > 0 ||
                      rp->count("--device") > 0 || rp->count("--drift") > 0;
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
    bool batch = false;
  };
  auto next = std::make_shared<NextArgs>();
  auto* n = app->add_subcommand("next-pose", "the most informative pose to capture next");
  SetManual(n, kNextPoseManual);
  AddCommon(n, &next->common);
  auto* device_option = n->add_option("--device", next->device, "device (default: the first)");
  n->add_flag(
       "--batch", next->batch,
       "the whole fixture: every unit still short of a gate planned together (docs/BATCH.md)")
      ->excludes(device_option);
  n->callback([next] {
    nlohmann::json request = {{"cmd", "next_pose"}};
    if (!next->device.empty()) request["device"] = next->device;
    if (next->batch) request["batch"] = true;
    throw CLI::RuntimeError(Simple("next-pose", next->common, request, PrintNextPose));
  });

  // watch, pose and rate (watch_command.cc, pose_command.cc): here, in --help's order.
  AddWatchCommand(app);
  AddPoseCommands(app);

  struct ResetArgs {
    Common common;
    std::string note;
  };
  auto reset = std::make_shared<ResetArgs>();
  auto* rs = app->add_subcommand("reset", "start a new session (the current one is archived)");
  SetManual(rs, kResetManual);
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
  SetManual(pb, kPublishManual);
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
