#include "tools/report_command.h"

#include <fmt/format.h>

#include <chrono>
#include <ctime>
#include <filesystem>
#include <nlohmann/json.hpp>

#include "daemon/state/atomic_file.h"
#include "daemon/state/batch_file.h"
#include "daemon/state/device_write_record.h"
#include "drivers/transport/transport.h"
#include "report/html.h"
#include "tools/client_connection.h"
#include "tools/report_state_dir.h"

namespace turncal::tools {
namespace {

int Fail(const std::string& message) {
  fmt::print(stderr, "turncal report: {}\n", message);
  return 2;
}

// The running daemon's state directory (`status` names it).
bool DaemonStateDir(const std::string& socket, std::string* state_dir, std::string* error) {
  ClientConnection conn;
  if (!conn.Connect(socket, error)) return false;
  const auto reply = conn.Request({{"cmd", "status"}}, error);
  if (!reply) return false;
  if (reply->value("class", "") == "ERROR") {
    *error = reply->value("message", "error");
    return false;
  }
  const auto it = reply->find("state_dir");
  if (it == reply->end() || !it->is_string() || it->get<std::string>().empty()) {
    *error =
        "the daemon keeps no state directory, so it has no calibrations to report "
        "(give --state-dir DIR)";
    return false;
  }
  *state_dir = it->get<std::string>();
  return true;
}

}  // namespace

std::string ReportPathForDevice(const std::string& output, const std::string& device) {
  const std::filesystem::path p(output);
  return (p.parent_path() / (p.stem().string() + "." + device + p.extension().string())).string();
}

int RunHtmlReport(const HtmlReportArgs& args) {
  if (args.output.empty()) return Fail("-o needs a file name");
  std::string error;
  std::string state_dir = args.state_dir;
  if (state_dir.empty() && !DaemonStateDir(args.socket, &state_dir, &error)) {
    return Fail(error);
  }
  std::map<std::string, DeviceCalibrations> devices;
  if (!ReadStateDirCalibrations(state_dir, args.device, &devices, &error)) return Fail(error);
  const bool several = devices.size() > 1;
  report::ReportOptions options;
  options.source = state_dir;
  options.generated_utc = drivers::UtcNowIso8601();
  if (!args.drift.empty() && !ReadDriftFile(args.drift, &options.drift, &error)) return Fail(error);
  for (auto& [device, d] : devices) {
    for (std::size_t i = 0; i < d.calibrations.size(); ++i) {
      const std::string note = AttachJournalRecords(state_dir, &d.calibrations[i]);
      if (!note.empty()) fmt::print(stderr, "turncal report: {}: {}\n", d.paths[i], note);
    }
    options.device_writes = daemon::ReadDeviceWriteHistory(state_dir, device);
    options.batch = daemon::ReadBatchStatus(state_dir);
    std::string html;
    if (!report::RenderReportHtml(d.calibrations, options, &html, &error)) {
      std::string files;
      for (const auto& p : d.paths) files += (files.empty() ? "" : ", ") + p;
      return Fail(fmt::format("{} ({})", error, files));
    }
    const std::string path = several ? ReportPathForDevice(args.output, device) : args.output;
    if (!daemon::WriteFileAtomically(path, html, &error)) return Fail(error);
    std::vector<std::string> models;
    for (const auto& c : d.calibrations) models.push_back(c.value("model", "?"));
    if (args.json) {
      fmt::print("{}\n", nlohmann::json{{"class", "REPORT"},
                                        {"device", device},
                                        {"path", path},
                                        {"bytes", html.size()},
                                        {"models", models}}
                             .dump());
    } else {
      std::string names;
      for (const auto& m : models) names += (names.empty() ? "" : ", ") + m;
      fmt::print("{}\t{}: {} ({} bytes)\n", path, device, names, html.size());
    }
  }
  return 0;
}

}  // namespace turncal::tools
