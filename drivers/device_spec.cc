#include "drivers/device_spec.h"

#include <algorithm>
#include <cctype>
#include <charconv>

namespace turncal::drivers {

const char* ToString(Protocol protocol) {
  switch (protocol) {
    case Protocol::kMip:
      return "mip";
    case Protocol::kGx2:
      return "gx2";
    case Protocol::kXbus:
      return "xbus";
    case Protocol::kXbusLegacy:
      return "xbus-legacy";
  }
  return "?";
}

std::optional<Protocol> ParseProtocol(std::string_view text) {
  for (Protocol p : {Protocol::kMip, Protocol::kGx2, Protocol::kXbus, Protocol::kXbusLegacy}) {
    if (text == ToString(p)) return p;
  }
  return std::nullopt;
}

std::optional<DeviceSpec> ParseDeviceSpec(std::string_view text, std::string* error) {
  auto fail = [&](const std::string& why) -> std::optional<DeviceSpec> {
    if (error)
      *error = "device '" + std::string(text) + "': " + why + " (want NAME=PROTOCOL:PORT[@BAUD])";
    return std::nullopt;
  };
  const auto eq = text.find('=');
  if (eq == std::string_view::npos || eq == 0) return fail("missing NAME=");
  DeviceSpec spec;
  spec.name = std::string(text.substr(0, eq));
  const bool name_ok = std::all_of(spec.name.begin(), spec.name.end(), [](unsigned char c) {
    return std::isalnum(c) || c == '_' || c == '-' || c == '.';
  });
  if (!name_ok) return fail("NAME may hold letters, digits, '_', '-' and '.' only");
  std::string_view rest = text.substr(eq + 1);
  const auto colon = rest.find(':');
  if (colon == std::string_view::npos) return fail("missing PROTOCOL:");
  const auto protocol = ParseProtocol(rest.substr(0, colon));
  if (!protocol)
    return fail("unknown protocol '" + std::string(rest.substr(0, colon)) +
                "' (mip, gx2, xbus, xbus-legacy)");
  spec.protocol = *protocol;
  std::string_view port = rest.substr(colon + 1);
  // A baud suffix is the digits after the last '@'; tcp://host:port has no '@'.
  const auto at = port.rfind('@');
  if (at != std::string_view::npos) {
    std::string_view baud = port.substr(at + 1);
    int value = 0;
    const auto [ptr, ec] = std::from_chars(baud.data(), baud.data() + baud.size(), value);
    if (ec != std::errc() || ptr != baud.data() + baud.size() || value < 300 || value > 4000000) {
      return fail("BAUD must be a number from 300 to 4000000");
    }
    spec.baud = value;
    port = port.substr(0, at);
  }
  if (port.empty()) return fail("missing PORT");
  spec.port = std::string(port);
  return spec;
}

}  // namespace turncal::drivers
