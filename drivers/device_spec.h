#pragma once
// A device on the command line: NAME=PROTOCOL:PORT[@BAUD] (DESIGN.md "Command line").
// PORT is a device path, tcp://HOST:PORT or replay:FILE.

#include <optional>
#include <string>
#include <string_view>

namespace turncal::drivers {

enum class Protocol { kMip, kGx2, kXbus, kXbusLegacy };

// "mip", "gx2", "xbus", "xbus-legacy".
const char* ToString(Protocol protocol);
std::optional<Protocol> ParseProtocol(std::string_view text);

struct DeviceSpec {
  std::string name;
  Protocol protocol = Protocol::kMip;
  std::string port;
  int baud = 115200;
};

// Parses NAME=PROTOCOL:PORT[@BAUD]; nullopt with a message naming what is wrong.
std::optional<DeviceSpec> ParseDeviceSpec(std::string_view text, std::string* error);

}  // namespace turncal::drivers
