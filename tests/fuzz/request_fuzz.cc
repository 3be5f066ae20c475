// libFuzzer target for turncald's request parsing (protocol/messages.h; docs/protocol.md
// "Connection and framing", "Requests"): a client's bytes through RequestFramer, each line through
// ParseRequestLine and ParseCommand, and each command's arguments through its Parse*Request,
// exactly as daemon/service/socket_server.cc and daemon/service/service.cc call them -- everything
// before a request acts on the daemon.
//
// Input: byte 0 chooses the line cap (the real 65536 bytes, or 1 to 128 so that the fuzzer
// reaches oversized lines), the rest is the client's byte stream, split into reads whose sizes
// come from the stream itself.
//
// Invariants checked on every input:
// - nothing escapes as an exception; every refusal has a message;
// - the framer's lines and refusals are those of the whole stream split at '\n' (a trailing '\r'
//   removed, a line longer than the cap refused), whatever the reads it arrived in;
// - a request is a JSON object that writes back to itself (the reply's "id" is a copy); a line
//   with a NUL byte is not JSON;
// - a documented argument of another JSON type is refused, never read as absent;
// - an accepted command is a known one; an accepted pose has finite angles, an index in
//   [0, 2^31 - 1] (or none) and a dwell in (0, 3600] s; an accepted watch a finite
//   max_rate_hz >= 0 and a sample interval >= 0; an accepted publish names device, model,
//   operator and reason.
//
// Run: tests/fuzz/run_fuzz.sh BUILD_DIR SECONDS request
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "core/sequencing/sequencer.h"
#include "protocol/messages.h"

namespace {

namespace protocol = turncal::protocol;

struct Item {
  bool refused = false;  // a line longer than the cap
  std::string line;
};

// The lines of the whole stream, as the framer must give them.
std::vector<Item> Expected(std::string_view stream, std::size_t cap) {
  std::vector<Item> items;
  std::size_t start = 0;
  for (std::size_t nl; (nl = stream.find('\n', start)) != std::string_view::npos; start = nl + 1) {
    std::string line(stream.substr(start, nl - start));
    if (!line.empty() && line.back() == '\r') line.pop_back();
    if (line.size() > cap) {
      items.push_back({true, ""});
    } else {
      items.push_back({false, line});
    }
  }
  // The unfinished line: refused once longer than the cap (a last '\r' may be that of "\r\n").
  const std::string_view rest = stream.substr(start);
  if (rest.size() - (!rest.empty() && rest.back() == '\r' ? 1 : 0) > cap)
    items.push_back({true, ""});
  return items;
}

// The documented arguments (docs/protocol.md "Requests") and their JSON types: a request that
// has one of another type is refused, never read as absent or as a default.
enum class Type { kNumber, kInteger, kString, kBoolean };

bool HasWrongType(const nlohmann::json& request, const std::string& cmd) {
  struct Argument {
    const char* cmd;
    const char* key;
    Type type;
  };
  static const Argument kArguments[] = {
      {"pose", "phi_deg", Type::kNumber},       {"pose", "gamma_deg", Type::kNumber},
      {"pose", "psi_deg", Type::kNumber},       {"pose", "index", Type::kInteger},
      {"pose", "dwell_s", Type::kNumber},       {"pose", "device", Type::kString},
      {"watch", "enable", Type::kBoolean},      {"watch", "events", Type::kBoolean},
      {"watch", "corrected", Type::kBoolean},   {"watch", "raw", Type::kBoolean},
      {"watch", "uncertainty", Type::kBoolean}, {"watch", "device", Type::kString},
      {"watch", "max_rate_hz", Type::kNumber},  {"next_pose", "device", Type::kString},
      {"next_pose", "batch", Type::kBoolean},   {"reset", "note", Type::kString},
      {"publish", "override", Type::kBoolean},  {"publish", "device", Type::kString},
      {"publish", "model", Type::kString},      {"publish", "operator", Type::kString},
      {"publish", "reason", Type::kString},
  };
  // {"enable":false} stops watching: the other arguments do not matter.
  if (cmd == "watch" && request.contains("enable") && request["enable"] == false) return false;
  for (const auto& a : kArguments) {
    if (cmd != a.cmd || !request.contains(a.key)) continue;
    const auto& v = request[a.key];
    const bool ok = a.type == Type::kNumber    ? v.is_number()
                    : a.type == Type::kInteger ? v.is_number_integer()
                    : a.type == Type::kString  ? v.is_string()
                                               : v.is_boolean();
    if (!ok) return true;
  }
  return false;
}

void CheckRequest(const std::string& line) {
  nlohmann::json request;
  std::string error;
  const auto kind = protocol::ParseRequestLine(line, &request, &error);
  const bool blank = line.find_first_not_of(" \t") == std::string::npos;
  if (blank != (kind == protocol::RequestLine::kBlank)) __builtin_trap();
  if (kind == protocol::RequestLine::kBlank) return;
  if (kind == protocol::RequestLine::kError) {
    if (error.empty()) __builtin_trap();
    return;
  }
  // JSON text holds no NUL byte.
  if (!request.is_object() || line.find('\0') != std::string::npos) __builtin_trap();
  if (nlohmann::json::parse(request.dump()) != request) __builtin_trap();
  std::string cmd;
  if (!protocol::ParseCommand(request, &cmd, &error)) {
    if (error.empty()) __builtin_trap();
    return;
  }
  if (!request["cmd"].is_string() || request["cmd"].get<std::string>() != cmd) __builtin_trap();
  error.clear();
  // Each command's parser below must refuse it.
  const bool wrong_type = HasWrongType(request, cmd);
  if (cmd == "pose") {
    turncal::Announcement a;
    std::string device;
    if (!protocol::ParsePoseRequest(request, 7, &a, &device, &error)) {
      if (error.empty()) __builtin_trap();
      return;
    }
    if (wrong_type) __builtin_trap();
    if (!std::isfinite(a.pose.phi_rad) || !std::isfinite(a.pose.gamma_rad) ||
        !std::isfinite(a.pose.psi_rad) || a.t_host_ns != 7 ||
        (request.contains("index") ? a.index < 0 : a.index != -1) ||
        (a.dwell_s && !(*a.dwell_s > 0 && *a.dwell_s <= 3600))) {
      __builtin_trap();
    }
    if (!device.empty() && request["device"] != device) __builtin_trap();
  } else if (cmd == "watch") {
    std::optional<protocol::WatchSpec> spec;
    if (!protocol::ParseWatchRequest(request, &spec, &error)) {
      if (error.empty()) __builtin_trap();
      return;
    }
    if (wrong_type) __builtin_trap();
    if (spec) {
      if (!std::isfinite(spec->max_rate_hz) || spec->max_rate_hz < 0) __builtin_trap();
      if (spec->MinIntervalNs() < 0) __builtin_trap();
      if (!spec->device.empty() && request["device"] != spec->device) __builtin_trap();
    }
  } else if (cmd == "next_pose") {
    std::string device;
    bool batch = false;
    if (!protocol::ParseNextPoseRequest(request, &device, &batch, &error)) {
      if (error.empty()) __builtin_trap();
      return;
    }
    if (wrong_type) __builtin_trap();
    if (!device.empty() && request["device"] != device) __builtin_trap();
    if (batch && (!device.empty() || request["batch"] != true)) __builtin_trap();
  } else if (cmd == "reset") {
    std::string note;
    if (!protocol::ParseResetRequest(request, &note, &error)) {
      if (error.empty()) __builtin_trap();
      return;
    }
    if (wrong_type) __builtin_trap();
    if (!note.empty() && request["note"] != note) __builtin_trap();
  } else if (cmd == "publish") {
    protocol::PublishRequest p;
    if (!protocol::ParsePublishRequest(request, &p, &error)) {
      if (error.empty()) __builtin_trap();
      return;
    }
    if (wrong_type) __builtin_trap();
    if (p.device.empty() || p.model.empty() || p.operator_name.empty() || p.reason.empty() ||
        request["override"] != true) {
      __builtin_trap();
    }
  }
}

void Check(const std::uint8_t* data, std::size_t size) {
  if (size == 0) return;
  const std::size_t cap = data[0] < 128 ? protocol::kMaxRequestBytes : 1 + data[0] % 128;
  const std::string_view stream(reinterpret_cast<const char*>(data) + 1, size - 1);
  protocol::RequestFramer framer(cap);
  std::vector<Item> got;
  const auto on_line = [&](const std::string& line) {
    if (line.size() > cap || line.find('\n') != std::string::npos) __builtin_trap();
    got.push_back({false, line});
    CheckRequest(line);
    return true;
  };
  const auto on_error = [&](const std::string& message) {
    if (message.empty()) __builtin_trap();
    got.push_back({true, ""});
    return true;
  };
  std::size_t at = 0;
  while (at < stream.size()) {
    // Reads from 1 byte to a few kB, sized by the stream's own bytes.
    const auto c = static_cast<unsigned char>(stream[at]);
    const std::size_t n =
        std::min<std::size_t>(stream.size() - at, c < 200 ? 1 + c % 31 : 1 + (c - 200) * 64);
    if (!framer.Push(stream.substr(at, n), on_line, on_error)) __builtin_trap();
    at += n;
  }
  const auto expected = Expected(stream, cap);
  if (got.size() != expected.size()) __builtin_trap();
  for (std::size_t i = 0; i < got.size(); ++i) {
    if (got[i].refused != expected[i].refused || got[i].line != expected[i].line) __builtin_trap();
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  try {
    Check(data, size);
  } catch (...) {
    __builtin_trap();  // an exception out of a request handler ends turncald
  }
  return 0;
}
