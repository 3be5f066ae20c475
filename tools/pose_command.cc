#include "tools/pose_command.h"

#include <fmt/format.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <memory>
#include <set>

#include "tools/client_common.h"
#include "tools/help_text.h"

namespace turncal::tools {
namespace {

// The codes RunPose returns for `pose`.
constexpr Manual kPoseManual = {
    "Tells turncald that the table is at PHI GAMMA PSI (degrees: inner x, middle y, outer z "
    "axis) and waits until every device captured or rejected the pose. A controller script "
    "calls this after each move. Negative angles need no --. {socket}",
    "turncal pose 0 0 0\n"
    "turncal pose 90 45 -180 --dwell 5\n"
    "turncal pose 0 90 0 --device imu2 || echo \"rejected or failed: $?\"",
    "0 every device captured the pose; 1 some device rejected it (the reason is printed); 2 "
    "the daemon cannot be reached, an ERROR, no answer within --timeout, or a command-line "
    "mistake",
    "tools/examples/README.md (a whole controller), docs/SEQUENCER.md (why poses are "
    "rejected)"};

// The codes RunPose returns for `rate`.
constexpr Manual kRateManual = {
    "Tells turncald that the table turns about AXIS (outer, middle or inner) at RATE deg/s, "
    "the other axes at --phi/--gamma/--psi degrees, and waits until every device captured "
    "or rejected the rate segment: once the gyro's rate is steady, turncald averages it over "
    "whole revolutions (at least the dwell) for the gyroscope models (gyro12, gyro21). "
    "A controller calls this once the table turns steadily. {socket}",
    "turncal rate outer 100\n"
    "turncal rate outer -100 --gamma 90\n"
    "turncal rate inner 30 --dwell 20 || echo \"rejected or failed: $?\"",
    "0 every device captured the segment; 1 some device rejected it (the reason is printed: "
    "a rate that is not steady, or not the announced one); 2 the daemon cannot be reached, an "
    "ERROR, no answer within --timeout, or a command-line mistake",
    "docs/protocol.md (\"rate\"), docs/models.md (\"Gyroscope models\"), docs/SEQUENCER.md "
    "(\"Rate segments\")"};

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
                 ProgressBar(e.value("collected", 0.0) / needed, 30));
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

void AddPoseCommands(CLI::App* app) {
  auto pose = std::make_shared<PoseArgs>();
  auto* p = app->add_subcommand(
      "pose", "announce the table's pose (degrees) and wait until it is captured or rejected");
  SetManual(p, kPoseManual);
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
  SetManual(rt, kRateManual);
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
}

}  // namespace turncal::tools
