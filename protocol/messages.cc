#include "protocol/messages.h"

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

}  // namespace turncal::protocol
