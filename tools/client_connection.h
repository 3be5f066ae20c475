#pragma once
// The client side of the socket protocol (docs/protocol.md) for `turncal`: connect to a Unix
// socket, read the VERSION banner (the major version must match), send requests, read lines.
// Blocking, with timeouts; errors are sentences.

#include <chrono>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>

namespace turncal::tools {

// $TURNCAL_SOCKET, else /run/turncal/turncal.sock.
std::string DefaultSocketPath();

class ClientConnection {
 public:
  ~ClientConnection();
  // Connects and reads the banner. False with a message (no daemon, wrong protocol version).
  bool Connect(const std::string& path, std::string* error);
  bool Send(const nlohmann::json& request, std::string* error);
  // The next line; nullopt on timeout (*error empty) or when the daemon closed (message).
  std::optional<std::string> ReadLine(std::chrono::milliseconds timeout, std::string* error);
  // Sends `request` and returns the first reply whose class is not a stream message (DROPPED,
  // events and samples of a watch are skipped), or an ERROR reply. nullopt with a message.
  std::optional<nlohmann::json> Request(
      const nlohmann::json& request, std::string* error,
      std::chrono::milliseconds timeout = std::chrono::seconds(30));
  const nlohmann::json& banner() const { return banner_; }

 private:
  int fd_ = -1;
  std::string buffer_;
  nlohmann::json banner_;
};

}  // namespace turncal::tools
