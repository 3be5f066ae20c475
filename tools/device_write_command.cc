#include "tools/device_write_command.h"

#include <fmt/format.h>
#include <unistd.h>

#include <iostream>
#include <memory>
#include <string>

#include "tools/client_connection.h"
#include "tools/help_text.h"

namespace turncal::tools {

namespace {

struct DeviceWriteArgs {
  std::string socket = DefaultSocketPath();
  bool json = false;
  std::string device, model;
  bool save = false, dry_run = false, restore = false, yes = false, transform = false;
  double timeout_s = 120.0;
};

std::string Values(const nlohmann::json& v) {
  if (!v.is_array()) return "-";
  std::string out;
  for (const auto& x : v) {
    out += out.empty() ? "" : " ";
    out += x.is_number() ? fmt::format("{:+.7g}", x.get<double>()) : std::string("null");
  }
  return out;
}

void PrintPlan(const nlohmann::json& plan) {
  const bool restore = plan.value("operation", "") == "restore";
  if (restore) {
    const auto& w = plan["restores_write"];
    fmt::print(
        "{} (serial {}): restore the values held before turncal wrote into it (last: {} of {} "
        "v{}){}\n",
        plan.value("device", ""), plan.value("serial", ""), w.value("time", ""),
        w.value("model", ""), w.value("version", 0),
        plan.value("save", false) ? ", saved to non-volatile memory" : "");
  } else {
    fmt::print("{} (serial {}): write {} v{} into the device's stored calibration\n",
               plan.value("device", ""), plan.value("serial", ""), plan.value("model", ""),
               plan.value("version", 0));
  }
  for (const auto& w : plan.value("writes", nlohmann::json::array())) {
    const std::string unit = w.value("unit", "");
    fmt::print("  {} ({}, {}){}\n", w.value("name", ""), w.value("quantity", ""),
               w.value("descriptor", ""), unit.empty() ? "" : " [" + unit + "]");
    fmt::print("    stored now : {}\n", Values(w["stored"]));
    fmt::print("    to write   : {}\n", Values(w["to_write"]));
    if (w.contains("sigma")) fmt::print("    1 sigma    : {}\n", Values(w["sigma"]));
  }
  if (plan.contains("device_holds")) {
    fmt::print(
        "  (the device holds an earlier write; the values above are composed with those "
        "its calibrations were made with)\n");
  }
  for (const auto& c : plan.value("changes", nlohmann::json::array())) {
    fmt::print("  change: {}\n", c.get<std::string>());
  }
  for (const auto& k : plan.value("kept_in_stream", nlohmann::json::array())) {
    fmt::print("  stays in turncald's stream: {}\n", k.get<std::string>());
  }
  for (const auto& r : plan.value("refusals", nlohmann::json::array())) {
    fmt::print("  REFUSED: {}\n", r.get<std::string>());
  }
}

void PrintOutcome(const nlohmann::json& r) {
  fmt::print("{}: {} {}{}\n", r.value("device", ""), r.value("operation", ""), r.value("state", ""),
             r.value("ok", false) ? "" : " (FAILED)");
  for (const auto& line : r.value("log", nlohmann::json::array())) {
    fmt::print("  {}\n", line.get<std::string>());
  }
  if (!r.value("error", std::string()).empty()) {
    fmt::print("  error: {}\n", r.value("error", std::string()));
  }
  if (!r.value("rollback_error", std::string()).empty()) {
    fmt::print("  rollback error: {}\n", r.value("rollback_error", std::string()));
  }
  if (r.contains("verification") && r["verification"].is_object()) {
    fmt::print("  {}\n", r["verification"].value("summary", ""));
  }
  if (r.contains("history")) fmt::print("  recorded in {}\n", r.value("history", ""));
}

// The codes WriteFail and Run return.
constexpr Manual kDeviceWriteManual = {
    "Writes DEVICE's active calibration of MODEL into the device's stored calibration (MIP: "
    "accelerometer and gyro bias, hard-iron offset, soft-iron matrix), composed with what "
    "it stores now. Shows the plan first: the stored values, the values to write with their "
    "1 sigma, the expected change of the output, what stays in turncald's stream (scale "
    "factors and misalignments, which MIP cannot hold), and every refusal (gate not passed, "
    "another serial, other stored values than the calibration was made with, Xbus, GX2). "
    "With --transform it also writes the sensor-to-vehicle transform (0x33), so that the "
    "device outputs in the frame the calibration corrects into (every output turns). "
    "Then asks (or --yes), writes, reads back bit for bit, saves only with --save, and "
    "verifies by measurement: the device's uncorrected output after the write must be the "
    "output predicted from before it (0.1 % false alarms; a device that moved: at the next "
    "captured pose). A failure rolls back. The replaced "
    "values are kept in the state directory (device_writes/); --restore puts back what the "
    "device held before turncal wrote into it. "
    "Needs a permitted uid. {socket}",
    "turncal device-write imu1 --model mag13 --dry-run\n"
    "turncal device-write imu1 --model mag13 --save\n"
    "turncal device-write imu1 --restore",
    "0 written and verified (or --dry-run: the plan may be written); 1 written but not "
    "verified, not confirmed, or (--dry-run) refused; 2 refused, failed (the device is "
    "as it was, or the reply says its state), the daemon cannot be reached, or a "
    "command-line mistake",
    "docs/protocol.md (Writing a calibration into the device)"};

int WriteFail(const std::string& message) {
  fmt::print(stderr, "turncal device-write: {}\n", message);
  return 2;
}

int Run(const DeviceWriteArgs& a) {
  if (a.restore == !a.model.empty()) return WriteFail("give --model M (write) or --restore");
  ClientConnection conn;
  std::string error;
  if (!conn.Connect(a.socket, &error)) return WriteFail(error);
  nlohmann::json request = {{"cmd", "device_write"}, {"device", a.device}, {"save", a.save}};
  if (a.restore) {
    request["restore"] = true;
  } else {
    request["model"] = a.model;
    if (a.transform) request["transform"] = true;
  }
  nlohmann::json ask = request;
  ask["dry_run"] = true;
  auto plan_reply = conn.Request(ask, &error);
  if (!plan_reply) return WriteFail(error);
  if (a.json) fmt::print("{}\n", plan_reply->dump());
  if (plan_reply->value("class", "") == "ERROR") {
    return WriteFail(plan_reply->value("message", "error"));
  }
  const nlohmann::json plan = (*plan_reply)["plan"];
  if (!a.json) PrintPlan(plan);
  if (!plan.value("ok", false)) return a.dry_run ? 1 : 2;
  if (a.dry_run) return 0;
  if (!a.yes) {
    if (!::isatty(STDIN_FILENO)) {
      return WriteFail("not written: no terminal to ask on; add --yes to write without asking");
    }
    fmt::print("Write these values into {}? [y/N] ", a.device);
    std::fflush(stdout);
    std::string answer;
    std::getline(std::cin, answer);
    if (answer != "y" && answer != "Y" && answer != "yes") {
      fmt::print("not written\n");
      return 1;
    }
  }
  if (!a.restore) request["version"] = plan.value("version", 0);
  auto reply = conn.Request(request, &error,
                            std::chrono::milliseconds(static_cast<long>(a.timeout_s * 1000)));
  if (!reply) return WriteFail(error + " (the write may still be under way: turncal status)");
  if (a.json) fmt::print("{}\n", reply->dump());
  if (reply->value("class", "") == "ERROR") return WriteFail(reply->value("message", "error"));
  if (!a.json) PrintOutcome(*reply);
  if (!reply->value("ok", false)) return 2;
  const bool verified =
      reply->contains("verification") && (*reply)["verification"].value("pass", false);
  return verified ? 0 : 1;
}

}  // namespace

void AddDeviceWriteCommand(CLI::App* app) {
  auto args = std::make_shared<DeviceWriteArgs>();
  auto* cmd = app->add_subcommand(
      "device-write", "write a device's active calibration into its stored calibration (MIP)");
  SetManual(cmd, kDeviceWriteManual);
  cmd->add_option("--socket", args->socket, "turncald's socket ($TURNCAL_SOCKET)")
      ->capture_default_str();
  cmd->add_flag("--json", args->json, "print the daemon's JSON replies, one object a line");
  cmd->add_option("device", args->device, "device")->required();
  cmd->add_option("--model", args->model, "the calibration to write, e.g. mag13");
  cmd->add_flag("--save", args->save, "also save to non-volatile memory (survives a restart)");
  cmd->add_flag("--dry-run", args->dry_run, "show the plan only; write nothing");
  cmd->add_flag("--transform", args->transform,
                "also write the sensor-to-vehicle transform (0x33): the device then outputs in "
                "the frame the calibration corrects into (it turns every output)");
  cmd->add_flag("--restore", args->restore,
                "put back the values the device held before turncal wrote into it");
  cmd->add_flag("--yes", args->yes, "write without asking (scripts)");
  cmd->add_option("--timeout", args->timeout_s, "give up waiting after this many seconds")
      ->capture_default_str();
  cmd->callback([args] { throw CLI::RuntimeError(Run(*args)); });
}

}  // namespace turncal::tools
