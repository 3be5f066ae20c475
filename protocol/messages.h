#pragma once
// The socket protocol (DESIGN.md "Socket protocol"): JSON Lines over a Unix stream socket. Each
// request has a "cmd"; each reply and event a "class".

#include <cstdint>
#include <functional>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <string_view>

namespace turncal {
struct Announcement;  // core/sequencing/sequencer.h
}  // namespace turncal

namespace turncal::protocol {

inline constexpr int kProtoMajor = 1;
inline constexpr int kProtoMinor = 1;  // 1.1: the "rate" command (issue 21)
// Longest request line the server reads; longer lines are answered with ERROR and dropped.
inline constexpr std::size_t kMaxRequestBytes = 64 * 1024;

// The greeting sent on connect: {"class":"VERSION","release":...,"proto_major":1,"proto_minor":1}.
nlohmann::json VersionMessage();

// {"class":"ERROR","message":...}.
nlohmann::json ErrorMessage(const std::string& message);

// Requests (docs/protocol.md "Connection and framing", "Requests"). The server splits a client's
// bytes into lines (RequestFramer), each line into a JSON object (ParseRequestLine) and names its
// command (ParseCommand); each command's arguments are checked by its Parse*Request before
// anything happens. Every refusal is an ERROR's message, never empty.

// The commands, as an ERROR lists them.
inline constexpr const char* kCommands =
    "status, devices, pose, rate, watch, result, next_pose, reset, publish, device_write, "
    "version, chamber, noise";
// pose, rate, reset, publish, device_write and chamber change the session or a device: only
// control peers
// may send them.
bool IsMutatingCommand(const std::string& cmd);

// Splits a client's bytes into request lines: '\n' ends a line, a trailing '\r' is removed. A
// line longer than `max_bytes` is refused: as soon as more than `max_bytes` of it have arrived
// without its newline (the rest is dropped up to its newline), or when it ends.
class RequestFramer {
 public:
  // Each handler returns false to stop (the session closed): the bytes after that line are then
  // not looked at.
  using LineHandler = std::function<bool(const std::string& line)>;  // blank lines too
  using ErrorHandler = std::function<bool(const std::string& message)>;

  explicit RequestFramer(std::size_t max_bytes = kMaxRequestBytes) : max_bytes_(max_bytes) {}
  // False when a handler stopped.
  bool Push(std::string_view bytes, const LineHandler& on_line, const ErrorHandler& on_error);
  std::size_t pending_bytes() const { return line_.size(); }
  bool discarding() const { return discarding_; }

 private:
  std::size_t max_bytes_;
  std::string line_;
  bool discarding_ = false;  // inside an oversized request, up to its newline
};

// Arrays and objects nested deeper than this in a request are refused before parsing.
inline constexpr int kMaxRequestDepth = 64;

enum class RequestLine {
  kBlank,    // empty or only blanks: nothing to answer
  kRequest,  // *request is a JSON object
  kError,    // *error is the ERROR's message (not JSON, not an object)
};
RequestLine ParseRequestLine(const std::string& line, nlohmann::json* request, std::string* error);

// The request's "cmd": false with the ERROR's message when it is missing, not a string, or no
// command.
bool ParseCommand(const nlohmann::json& request, std::string* cmd, std::string* error);

// What a watching client asked for.
struct WatchSpec {
  bool events = true;
  bool corrected = false;
  bool raw = false;
  std::string device;        // empty: every device
  double max_rate_hz = 0.0;  // per device, for samples; <= 0: every sample
  bool uncertainty = false;  // corrected samples carry the calibration's 1 sigma per axis

  // The least time between two samples of one device, for max_rate_hz (0: every sample).
  std::int64_t MinIntervalNs() const;
};

// watch: *spec empty for {"enable":false} (stop watching).
bool ParseWatchRequest(const nlohmann::json& request, std::optional<WatchSpec>* spec,
                       std::string* error);

// pose: the announcement (ParsePoseCommand) and the one device it is for (empty: every device).
bool ParsePoseRequest(const nlohmann::json& request, std::int64_t t_host_ns, Announcement* out,
                      std::string* device, std::string* error);

// next_pose: the device asked about (empty: none named), or the whole fixture ("batch": true;
// docs/BATCH.md). `batch` may be null: then "batch" is refused.
bool ParseNextPoseRequest(const nlohmann::json& request, std::string* device, bool* batch,
                          std::string* error);
// {"cmd":"chamber","setpoint_c":40}: the chamber soaks at 40 degC (announced poses wait for the
// sensor's temperature to settle); "setpoint_c": null or absent: a ramp, or no chamber.
bool ParseChamberRequest(const nlohmann::json& request, std::optional<double>* setpoint_c,
                         std::string* error);

// {"cmd":"noise","device":"imu1","action":"start"|"status"|"stop"}: a rest's noise on a device
// (docs/NOISE.md); the action defaults to "status", the device to "" (the caller's first).
bool ParseNoiseRequest(const nlohmann::json& request, std::string* device, std::string* action,
                       std::string* error);

// reset: its note (empty: none).
bool ParseResetRequest(const nlohmann::json& request, std::string* note, std::string* error);

// publish: an operator's override of the gate.
struct PublishRequest {
  std::string device;
  std::string model;
  std::string operator_name;
  std::string reason;
};
bool ParsePublishRequest(const nlohmann::json& request, PublishRequest* out, std::string* error);

// device_write: DEVICE's active calibration of MODEL into the device's stored calibration (issue
// 23, docs/protocol.md "Writing a calibration into the device"), or with `restore` the values it
// held before turncal's writes back into it.
struct DeviceWriteArgs {
  std::string device;
  std::string model;  // not with restore
  bool save = false;  // also to non-volatile memory
  bool dry_run = false;
  bool restore = false;
  bool transform = false;      // also the sensor-to-vehicle transform (0x33)
  std::optional<int> version;  // the version the plan showed: refused when another is active
};
bool ParseDeviceWriteRequest(const nlohmann::json& request, DeviceWriteArgs* out,
                             std::string* error);

}  // namespace turncal::protocol
