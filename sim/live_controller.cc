#include "sim/live_controller.h"

#include <fcntl.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>

namespace turncal::sim::live {

bool Controller::TryConnect() {
  sockaddr_un address{};
  address.sun_family = AF_UNIX;
  if (path_.size() >= sizeof(address.sun_path)) return false;
  std::memcpy(address.sun_path, path_.data(), path_.size());
  fd_ = ::socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0);
  if (fd_ < 0) return false;
  if (::connect(fd_, reinterpret_cast<const sockaddr*>(&address), sizeof(address)) != 0) {
    Close();
    return false;
  }
  ::fcntl(fd_, F_SETFL, O_NONBLOCK);
  buffer_.clear();
  return true;
}

void Controller::Close() {
  if (fd_ >= 0) ::close(fd_);
  fd_ = -1;
}

bool Controller::Send(const nlohmann::json& j) {
  const std::string text = j.dump() + "\n";
  const ssize_t n = ::send(fd_, text.data(), text.size(), MSG_NOSIGNAL);
  if (n != static_cast<ssize_t>(text.size())) {
    Close();
    return false;
  }
  return true;
}

bool Controller::Read(std::vector<nlohmann::json>* messages) {
  char chunk[65536];
  for (;;) {
    const ssize_t n = ::recv(fd_, chunk, sizeof(chunk), 0);
    if (n > 0) {
      buffer_.append(chunk, static_cast<std::size_t>(n));
      continue;
    }
    if (n < 0 && (errno == EAGAIN || errno == EWOULDBLOCK)) break;
    if (n < 0 && errno == EINTR) continue;
    Close();
    return false;
  }
  for (auto nl = buffer_.find('\n'); nl != std::string::npos; nl = buffer_.find('\n')) {
    auto j = nlohmann::json::parse(buffer_.substr(0, nl), nullptr, false);
    buffer_.erase(0, nl + 1);
    if (!j.is_discarded()) messages->push_back(std::move(j));
  }
  return true;
}

}  // namespace turncal::sim::live
