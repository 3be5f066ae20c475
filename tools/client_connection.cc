#include "tools/client_connection.h"

#include <fmt/format.h>
#include <poll.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <unistd.h>

#include <cerrno>
#include <cstdlib>
#include <cstring>

#include "protocol/messages.h"

namespace turncal::tools {

std::string DefaultSocketPath() {
  const char* env = std::getenv("TURNCAL_SOCKET");
  return env && *env ? env : "/run/turncal/turncal.sock";
}

ClientConnection::~ClientConnection() {
  if (fd_ >= 0) ::close(fd_);
}

bool ClientConnection::Connect(const std::string& path, std::string* error) {
  sockaddr_un address{};
  address.sun_family = AF_UNIX;
  if (path.size() >= sizeof(address.sun_path)) {
    *error = "socket path too long: " + path;
    return false;
  }
  std::memcpy(address.sun_path, path.data(), path.size());
  fd_ = ::socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0);
  if (fd_ < 0 ||
      ::connect(fd_, reinterpret_cast<const sockaddr*>(&address), sizeof(address)) != 0) {
    *error = fmt::format(
        "cannot connect to turncald at {}: {} (is turncald running? --socket or "
        "$TURNCAL_SOCKET name another socket)",
        path, std::strerror(errno));
    return false;
  }
  std::string why;
  auto line = ReadLine(std::chrono::seconds(5), &why);
  if (!line) {
    *error = fmt::format("{}: no VERSION banner{}", path, why.empty() ? "" : ": " + why);
    return false;
  }
  banner_ = nlohmann::json::parse(*line, nullptr, false);
  if (banner_.is_discarded() || banner_.value("class", "") != "VERSION") {
    *error = fmt::format("{}: not a turncald socket (first line: {})", path, line->substr(0, 80));
    return false;
  }
  if (banner_.value("proto_major", -1) != protocol::kProtoMajor) {
    *error = fmt::format("turncald speaks protocol {}.{}, this turncal {}.{}",
                         banner_.value("proto_major", -1), banner_.value("proto_minor", -1),
                         protocol::kProtoMajor, protocol::kProtoMinor);
    return false;
  }
  return true;
}

bool ClientConnection::Send(const nlohmann::json& request, std::string* error) {
  const std::string text = request.dump() + "\n";
  std::size_t done = 0;
  while (done < text.size()) {
    const ssize_t n = ::send(fd_, text.data() + done, text.size() - done, MSG_NOSIGNAL);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) {
      *error = std::string("turncald closed the connection: ") + std::strerror(errno);
      return false;
    }
    done += static_cast<std::size_t>(n);
  }
  return true;
}

std::optional<std::string> ClientConnection::ReadLine(std::chrono::milliseconds timeout,
                                                      std::string* error) {
  error->clear();
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  for (;;) {
    if (const auto nl = buffer_.find('\n'); nl != std::string::npos) {
      std::string line = buffer_.substr(0, nl);
      buffer_.erase(0, nl + 1);
      return line;
    }
    const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(
        deadline - std::chrono::steady_clock::now());
    if (left.count() <= 0) return std::nullopt;
    pollfd p{fd_, POLLIN, 0};
    const int r = ::poll(&p, 1, static_cast<int>(left.count()));
    if (r < 0 && errno == EINTR) continue;
    if (r == 0) return std::nullopt;
    char chunk[65536];
    const ssize_t n = ::recv(fd_, chunk, sizeof(chunk), 0);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) {
      *error = n == 0 ? "turncald closed the connection" : std::strerror(errno);
      return std::nullopt;
    }
    buffer_.append(chunk, static_cast<std::size_t>(n));
  }
}

std::optional<nlohmann::json> ClientConnection::Request(const nlohmann::json& request,
                                                        std::string* error,
                                                        std::chrono::milliseconds timeout) {
  if (!Send(request, error)) return std::nullopt;
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  for (;;) {
    const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(
        deadline - std::chrono::steady_clock::now());
    auto line = ReadLine(std::max(left, std::chrono::milliseconds(1)), error);
    if (!line) {
      if (error->empty()) *error = "no reply from turncald in time";
      return std::nullopt;
    }
    nlohmann::json j = nlohmann::json::parse(*line, nullptr, false);
    if (j.is_discarded()) continue;
    if (request.contains("id") && j.contains("id") && j["id"] == request["id"]) return j;
    if (!request.contains("id")) {
      const std::string kind = j.value("class", "");
      if (kind == "ERROR" && !j.contains("device")) return j;
      if (kind == "STATUS" || kind == "DEVICES" || kind == "RESULT" || kind == "NEXT_POSE" ||
          kind == "WATCH" || kind == "POSE_ACCEPTED" || kind == "RESET" || kind == "PUBLISHED" ||
          kind == "DEVICE_WRITE_PLAN" || kind == "DEVICE_WRITTEN" || kind == "VERSION" ||
          kind == "NOISE") {
        return j;
      }
    }
  }
}

}  // namespace turncal::tools
