#include "protocol/messages.h"

#include <cmath>

#include <algorithm>

#include <fmt/format.h>

#include <limits>

#include "core/sequencing/sequencer.h"
#include "protocol/sequencer_json.h"
#include "turncal/version.h"

namespace turncal::protocol {

nlohmann::json VersionMessage() {
  return {{"class", "VERSION"},
          {"release", kVersion},
          {"proto_major", kProtoMajor},
          {"proto_minor", kProtoMinor}};
}

nlohmann::json ErrorMessage(const std::string& message) {
  return {{"class", "ERROR"}, {"message", message}};
}

namespace {

// A string argument: "" when absent; false when it is there but not a string (json::value()
// would throw, and an exception out of a request handler ends turncald).
bool StringArgument(const nlohmann::json& request, const char* key, std::string* out) {
  const auto it = request.find(key);
  if (it == request.end()) {
    out->clear();
    return true;
  }
  if (!it->is_string()) return false;
  *out = it->get<std::string>();
  return true;
}

}  // namespace

bool IsMutatingCommand(const std::string& cmd) {
  return cmd == "pose" || cmd == "rate" || cmd == "reset" || cmd == "publish" ||
         cmd == "device_write" || cmd == "chamber";
}

bool RequestFramer::Push(std::string_view bytes, const LineHandler& on_line,
                         const ErrorHandler& on_error) {
  const std::size_t n = bytes.size();
  std::size_t start = 0;
  for (std::size_t i = 0; i < n; ++i) {
    if (bytes[i] != '\n') continue;
    bool go_on = true;
    if (discarding_) {
      discarding_ = false;
    } else {
      line_.append(bytes.data() + start, i - start);
      if (!line_.empty() && line_.back() == '\r') line_.pop_back();
      if (line_.size() > max_bytes_) {
        go_on = on_error(fmt::format("request longer than {} bytes: discarded", max_bytes_));
      } else {
        go_on = on_line(line_);
      }
    }
    line_.clear();
    start = i + 1;
    if (!go_on) return false;
  }
  if (discarding_) return true;
  line_.append(bytes.data() + start, n - start);
  // A '\r' at the end may be the one of "\r\n" and not count: a line is refused or not whatever
  // the reads it arrived in.
  const std::size_t cr = !line_.empty() && line_.back() == '\r' ? 1 : 0;
  if (line_.size() - cr > max_bytes_) {
    line_.clear();
    discarding_ = true;
    return on_error(
        fmt::format("request longer than {} bytes: discarded up to its end", max_bytes_));
  }
  return true;
}

namespace {

// The deepest nesting of arrays and objects in `line` (brackets inside strings do not count).
int NestingDepth(const std::string& line) {
  int depth = 0, deepest = 0;
  bool in_string = false, escaped = false;
  for (const char c : line) {
    if (in_string) {
      if (escaped) {
        escaped = false;
      } else if (c == '\\') {
        escaped = true;
      } else if (c == '"') {
        in_string = false;
      }
    } else if (c == '"') {
      in_string = true;
    } else if (c == '[' || c == '{') {
      deepest = std::max(deepest, ++depth);
    } else if (c == ']' || c == '}') {
      --depth;
    }
  }
  return deepest;
}

}  // namespace

RequestLine ParseRequestLine(const std::string& line, nlohmann::json* request, std::string* error) {
  if (line.find_first_not_of(" \t") == std::string::npos) return RequestLine::kBlank;
  // Copying, echoing and destroying a JSON value recurse once per level: 32 000 levels fit in a
  // 64 KiB line and took 4.6 MiB of stack (a stack overflow under AddressSanitizer, or with a
  // 4 MiB stack limit). No request needs more than a few.
  if (NestingDepth(line) > kMaxRequestDepth) {
    *error = fmt::format("malformed request: nested deeper than {} levels", kMaxRequestDepth);
    return RequestLine::kError;
  }
  // JSON text never holds a NUL byte, but the parser takes one for the end of its input
  // ({"cmd":"status"}\0garbage passed).
  const bool nul = line.find('\0') != std::string::npos;
  if (!nul) *request = nlohmann::json::parse(line, nullptr, false);
  if (nul || request->is_discarded()) {
    *error = "malformed request: not JSON (one object per line)";
    return RequestLine::kError;
  }
  if (!request->is_object()) {
    *error = "malformed request: a JSON object with \"cmd\" expected";
    return RequestLine::kError;
  }
  return RequestLine::kRequest;
}

bool ParseCommand(const nlohmann::json& request, std::string* cmd, std::string* error) {
  if (!request.contains("cmd") || !request["cmd"].is_string()) {
    *error = std::string("malformed request: no \"cmd\" (commands: ") + kCommands + ")";
    return false;
  }
  *cmd = request["cmd"].get<std::string>();
  for (const char* known : {"status", "devices", "pose", "rate", "watch", "result", "next_pose",
                            "reset", "publish", "device_write", "version", "chamber", "noise"}) {
    if (*cmd == known) return true;
  }
  *error = fmt::format("unknown command '{}' (commands: {})", *cmd, kCommands);
  return false;
}

std::int64_t WatchSpec::MinIntervalNs() const {
  if (!(max_rate_hz > 0)) return 0;
  const double ns = 1e9 / max_rate_hz;
  // Below 1.1e-10 Hz the interval is beyond 2^63 ns (292 years; converting it was undefined).
  return ns < 9.2e18 ? static_cast<std::int64_t>(ns) : std::numeric_limits<std::int64_t>::max();
}

bool ParseWatchRequest(const nlohmann::json& request, std::optional<WatchSpec>* spec,
                       std::string* error) {
  if (const auto it = request.find("enable"); it != request.end()) {
    if (!it->is_boolean()) {
      *error = "watch: 'enable' must be true or false";
      return false;
    }
    if (!it->get<bool>()) {
      spec->reset();
      return true;
    }
  }
  WatchSpec w;
  auto flag = [&](const char* key, bool* out) {
    if (!request.contains(key)) return true;
    if (!request[key].is_boolean()) return false;
    *out = request[key].get<bool>();
    return true;
  };
  bool ok = flag("events", &w.events) && flag("corrected", &w.corrected) && flag("raw", &w.raw) &&
            flag("uncertainty", &w.uncertainty);
  if (ok && request.contains("device")) {
    ok = request["device"].is_string();
    if (ok) w.device = request["device"].get<std::string>();
  }
  if (ok && request.contains("max_rate_hz")) {
    ok = request["max_rate_hz"].is_number() && request["max_rate_hz"].get<double>() >= 0;
    if (ok) w.max_rate_hz = request["max_rate_hz"].get<double>();
  }
  if (!ok) {
    *error =
        "watch: events, corrected, raw, uncertainty are true/false, device a name, "
        "max_rate_hz >= 0";
    return false;
  }
  *spec = w;
  return true;
}

bool ParsePoseRequest(const nlohmann::json& request, std::int64_t t_host_ns, Announcement* out,
                      std::string* device, std::string* error) {
  // ParsePoseCommand reads a capture's "event" before "cmd"; in a request "event" is a key the
  // daemon does not know, and is ignored (with it, a request got an ERROR with no message).
  if (request.contains("event")) {
    nlohmann::json without = request;
    without.erase("event");
    return ParsePoseRequest(without, t_host_ns, out, device, error);
  }
  bool is_pose = false;
  if (!ParsePoseCommand(request, t_host_ns, out, &is_pose, error)) {
    if (!is_pose) *error = "pose: not a pose or rate request";
    return false;
  }
  if (!StringArgument(request, "device", device)) {
    *error = "pose: 'device' must be a device name";
    return false;
  }
  return true;
}

bool ParseNextPoseRequest(const nlohmann::json& request, std::string* device, bool* batch,
                          std::string* error) {
  if (!StringArgument(request, "device", device)) {
    *error = "next_pose: 'device' must be a device name";
    return false;
  }
  if (batch) *batch = false;
  const auto it = request.find("batch");
  if (it == request.end()) return true;
  if (!batch || !it->is_boolean()) {
    *error = "next_pose: 'batch' must be true or false";
    return false;
  }
  *batch = it->get<bool>();
  if (*batch && !device->empty()) {
    *error = "next_pose: give 'device' or 'batch', not both";
    return false;
  }
  return true;
}

bool ParseChamberRequest(const nlohmann::json& request, std::optional<double>* setpoint_c,
                         std::string* error) {
  const auto it = request.find("setpoint_c");
  if (it == request.end() || it->is_null()) {
    setpoint_c->reset();
    return true;
  }
  if (!it->is_number() || !std::isfinite(it->get<double>()) || it->get<double>() < -273.15) {
    *error = "chamber: 'setpoint_c' must be a temperature in degC, or null (a ramp: no soak)";
    return false;
  }
  *setpoint_c = it->get<double>();
  return true;
}

bool ParseNoiseRequest(const nlohmann::json& request, std::string* device, std::string* action,
                       std::string* error) {
  if (!StringArgument(request, "device", device) || !StringArgument(request, "action", action)) {
    *error = "noise: 'device' and 'action' must be strings";
    return false;
  }
  if (action->empty()) *action = "status";
  if (*action != "start" && *action != "status" && *action != "stop") {
    *error = "noise: 'action' must be start, status or stop, not '" + *action + "'";
    return false;
  }
  return true;
}

bool ParseResetRequest(const nlohmann::json& request, std::string* note, std::string* error) {
  if (!StringArgument(request, "note", note)) {
    *error = "reset: 'note' must be a string";
    return false;
  }
  return true;
}

bool ParsePublishRequest(const nlohmann::json& request, PublishRequest* out, std::string* error) {
  PublishRequest p;
  const auto override_it = request.find("override");
  if (override_it == request.end() || *override_it != true ||
      !StringArgument(request, "device", &p.device) || p.device.empty() ||
      !StringArgument(request, "model", &p.model) || p.model.empty() ||
      !StringArgument(request, "operator", &p.operator_name) || p.operator_name.empty() ||
      !StringArgument(request, "reason", &p.reason) || p.reason.empty()) {
    *error =
        "publish: an explicit operator override needs \"override\":true, \"device\", \"model\", "
        "\"operator\" and \"reason\" (calibrations that pass the gate are published without "
        "asking)";
    return false;
  }
  *out = p;
  return true;
}

bool ParseDeviceWriteRequest(const nlohmann::json& request, DeviceWriteArgs* out,
                             std::string* error) {
  DeviceWriteArgs a;
  const auto flag = [&](const char* key, bool* value) {
    const auto it = request.find(key);
    if (it == request.end()) return true;
    if (!it->is_boolean()) return false;
    *value = it->get<bool>();
    return true;
  };
  if (!StringArgument(request, "device", &a.device) || a.device.empty()) {
    *error = "device_write: \"device\" (a device's name) is required";
    return false;
  }
  if (!StringArgument(request, "model", &a.model)) {
    *error = "device_write: \"model\" must be a string";
    return false;
  }
  if (!flag("save", &a.save) || !flag("dry_run", &a.dry_run) || !flag("restore", &a.restore) ||
      !flag("transform", &a.transform)) {
    *error = "device_write: \"save\", \"dry_run\", \"restore\" and \"transform\" are true or false";
    return false;
  }
  if (a.restore == !a.model.empty()) {
    *error =
        "device_write: either \"model\" (the calibration to write) or \"restore\":true (put "
        "back what the device held before turncal wrote into it)";
    return false;
  }
  if (const auto it = request.find("version"); it != request.end() && !it->is_null()) {
    if (!it->is_number_integer() || it->get<long long>() < 1 || it->get<long long>() > 1000000) {
      *error = "device_write: \"version\" is the calibration's version, a positive integer";
      return false;
    }
    a.version = it->get<int>();
  }
  *out = a;
  return true;
}

}  // namespace turncal::protocol
