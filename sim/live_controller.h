#pragma once
// The daemon's socket as the lab's controller in `turncal sim --live --controller` (sim/live.h)
// sees it: JSON lines both ways, non-blocking, connected again after the daemon restarts. For
// sim/live.cc only.

#include <nlohmann/json.hpp>
#include <string>
#include <vector>

namespace turncal::sim::live {

class Controller {
 public:
  explicit Controller(std::string path) : path_(std::move(path)) {}
  ~Controller() { Close(); }
  bool connected() const { return fd_ >= 0; }
  int fd() const { return fd_; }
  bool TryConnect();
  void Close();
  // False (and closed) when the line could not be sent whole.
  bool Send(const nlohmann::json& j);
  // Reads what arrived; false when the daemon closed the connection.
  bool Read(std::vector<nlohmann::json>* messages);

 private:
  std::string path_;
  int fd_ = -1;
  std::string buffer_;
};

}  // namespace turncal::sim::live
