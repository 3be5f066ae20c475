#include "daemon/service/socket_server.h"

#include <fmt/format.h>
#include <grp.h>
#include <pwd.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <unistd.h>

#include <boost/asio/post.hpp>
#include <boost/asio/write.hpp>
#include <cerrno>
#include <charconv>
#include <cstring>
#include <filesystem>

#include "protocol/messages.h"

namespace turncal::daemon {

namespace local = boost::asio::local;

bool ResolveUser(const std::string& name_or_uid, unsigned* uid, std::string* error) {
  if (!name_or_uid.empty() && name_or_uid.find_first_not_of("0123456789") == std::string::npos) {
    // Up to 2^32 - 2: (uid_t)-1 is no user. (std::stoul threw beyond 2^64 and wrapped beyond
    // 2^32 to another uid.)
    std::uint64_t value = 0;
    const char* end = name_or_uid.data() + name_or_uid.size();
    const auto [ptr, ec] = std::from_chars(name_or_uid.data(), end, value);
    if (ec != std::errc() || ptr != end || value > 4294967294u) {
      *error = "uid " + name_or_uid + " is out of range (0 to 4294967294)";
      return false;
    }
    *uid = static_cast<unsigned>(value);
    return true;
  }
  const passwd* p = ::getpwnam(name_or_uid.c_str());
  if (p == nullptr) {
    *error = "no user '" + name_or_uid + "'";
    return false;
  }
  *uid = p->pw_uid;
  return true;
}

SocketServer::SocketServer(boost::asio::io_context& io, SocketOptions options,
                           RequestHandler on_request)
    : io_(io), options_(std::move(options)), on_request_(std::move(on_request)) {}

SocketServer::~SocketServer() { Stop(); }

bool SocketServer::Listen(std::string* error) {
  namespace fs = std::filesystem;
  acceptor_ = std::make_unique<local::stream_protocol::acceptor>(io_);
  boost::system::error_code ec;
  if (options_.activated_fd) {
    acceptor_->assign(local::stream_protocol(), *options_.activated_fd, ec);
    if (ec) {
      *error = "cannot use the socket systemd passed: " + ec.message();
      return false;
    }
    Accept();
    return true;
  }
  const fs::path path(options_.path);
  std::error_code fec;
  if (path.has_parent_path()) fs::create_directories(path.parent_path(), fec);
  if (fs::exists(path, fec)) {
    // A socket file left by a crash is removed; one that still answers belongs to a running
    // turncald.
    local::stream_protocol::socket probe(io_);
    probe.connect(local::stream_protocol::endpoint(options_.path), ec);
    if (!ec) {
      *error = fmt::format("another turncald is listening on {}", options_.path);
      return false;
    }
    fs::remove(path, fec);
  }
  const mode_t old_mask = ::umask(0117);  // the socket is created 0660
  acceptor_->open(local::stream_protocol(), ec);
  if (!ec) acceptor_->bind(local::stream_protocol::endpoint(options_.path), ec);
  ::umask(old_mask);
  if (!ec) acceptor_->listen(64, ec);
  if (ec) {
    *error = fmt::format("cannot listen on {}: {}", options_.path, ec.message());
    return false;
  }
  created_file_ = true;
  ::chmod(options_.path.c_str(), 0660);
  if (!options_.group.empty()) {
    const group* g = ::getgrnam(options_.group.c_str());
    if (g == nullptr) {
      *error = fmt::format("socket group '{}' does not exist", options_.group);
      return false;
    }
    if (::chown(options_.path.c_str(), static_cast<uid_t>(-1), g->gr_gid) != 0) {
      *error = fmt::format("cannot give {} to group '{}': {}", options_.path, options_.group,
                           std::strerror(errno));
      return false;
    }
  }
  Accept();
  return true;
}

void SocketServer::Stop() {
  if (stopped_) return;
  stopped_ = true;
  if (acceptor_) {
    boost::system::error_code ignored;
    acceptor_->close(ignored);
  }
  auto sessions = sessions_;
  for (auto& [id, s] : sessions) s->Close();
  sessions_.clear();
  if (created_file_) {
    std::error_code ec;
    std::filesystem::remove(options_.path, ec);
  }
}

void SocketServer::Accept() {
  acceptor_->async_accept(
      [this](const boost::system::error_code& ec, local::stream_protocol::socket socket) {
        if (stopped_ || ec == boost::asio::error::operation_aborted) return;
        if (!ec) {
          ++accepted_;
          auto session = std::make_shared<ClientSession>(this, std::move(socket), next_id_++);
          sessions_[session->id()] = session;
          session->Start();
        }
        Accept();  // a failed accept (EMFILE) does not stop the server
      });
}

void SocketServer::Remove(std::uint64_t id) { sessions_.erase(id); }

void SocketServer::SetControlUids(std::set<unsigned> uids) {
  options_.control_uids = std::move(uids);
}

bool SocketServer::IsControl(unsigned uid) const {
  return uid == 0 || uid == ::geteuid() || options_.control_uids.count(uid) > 0;
}

ClientSession::ClientSession(SocketServer* server, local::stream_protocol::socket socket,
                             std::uint64_t id)
    : server_(server), socket_(std::move(socket)), id_(id) {
  ucred cred{};
  socklen_t size = sizeof(cred);
  if (::getsockopt(socket_.native_handle(), SOL_SOCKET, SO_PEERCRED, &cred, &size) == 0) {
    uid_ = cred.uid;
    pid_ = cred.pid;
    known_ = true;
  }
}

void ClientSession::Start() {
  Reply(protocol::VersionMessage());
  Read();
}

void ClientSession::Close() {
  if (!open_) return;
  open_ = false;
  boost::system::error_code ignored;
  socket_.shutdown(local::stream_protocol::socket::shutdown_both, ignored);
  socket_.close(ignored);
  pending_.clear();
  server_->Remove(id_);
}

void ClientSession::Read() {
  auto self = shared_from_this();
  socket_.async_read_some(boost::asio::buffer(buffer_),
                          [self](const boost::system::error_code& ec, std::size_t n) {
                            if (!self->open_) return;
                            if (ec) {
                              self->Close();
                              return;
                            }
                            self->OnBytes(n);
                            if (self->open_) self->Read();
                          });
}

void ClientSession::OnBytes(std::size_t n) {
  framer_.Push(
      {buffer_.data(), n},
      [this](const std::string& line) {
        nlohmann::json request;
        std::string error;
        switch (protocol::ParseRequestLine(line, &request, &error)) {
          case protocol::RequestLine::kBlank:
            break;
          case protocol::RequestLine::kError:
            Reply(protocol::ErrorMessage(error));
            break;
          case protocol::RequestLine::kRequest:
            server_->on_request_(shared_from_this(), request);
            break;
        }
        return open_;
      },
      [this](const std::string& message) {
        Reply(protocol::ErrorMessage(message));
        return open_;
      });
}

void ClientSession::Reply(const nlohmann::json& message) {
  std::string line = message.dump();
  line += '\n';
  Enqueue(line, false);
}

void ClientSession::Stream(const std::string& line) { Enqueue(line, true); }

void ClientSession::Enqueue(const std::string& line, bool droppable) {
  if (!open_) return;
  if (droppable && pending_.size() + line.size() > server_->options_.stream_queue_bytes) {
    ++dropped_;
    ++dropped_total_;
    return;
  }
  if (pending_.size() + line.size() > server_->options_.max_queue_bytes) {
    Close();  // it reads nothing and keeps asking: the only bound left is to let it go
    return;
  }
  if (dropped_ > 0 && droppable) {
    pending_ +=
        nlohmann::json{{"class", "DROPPED"}, {"count", dropped_}, {"total", dropped_total_}}.dump();
    pending_ += '\n';
    dropped_ = 0;
  }
  pending_ += line;
  if (writing_ || flush_posted_) return;  // the running write takes this line too
  // Written after the loop's current handlers: what this turn produced (the samples of every
  // device that was ready) goes out in one send. (A timer that waited 0.5 ms to gather more
  // samples a send cost more CPU than the sends it saved: docs/PERFORMANCE.md.)
  flush_posted_ = true;
  boost::asio::post(socket_.get_executor(), [self = shared_from_this()] {
    self->flush_posted_ = false;
    self->Write();
  });
}

void ClientSession::Write() {
  while (open_ && !pending_.empty()) {
    // Everything waiting goes out in one send; the two buffers keep their capacity.
    out_.swap(pending_);
    pending_.clear();
    // A non-blocking send first: a reading client takes the bytes now, without a trip through the
    // reactor. What the socket does not take is written asynchronously.
    const ssize_t n =
        ::send(socket_.native_handle(), out_.data(), out_.size(), MSG_DONTWAIT | MSG_NOSIGNAL);
    if (n < 0 && errno != EAGAIN && errno != EWOULDBLOCK && errno != EINTR) {
      Close();
      return;
    }
    const std::size_t sent = n > 0 ? static_cast<std::size_t>(n) : 0;
    if (sent == out_.size()) continue;
    out_.erase(0, sent);
    writing_ = true;
    auto self = shared_from_this();
    boost::asio::async_write(socket_, boost::asio::buffer(out_),
                             [self](const boost::system::error_code& ec, std::size_t) {
                               self->writing_ = false;
                               if (!self->open_) return;
                               if (ec) {
                                 self->Close();
                                 return;
                               }
                               self->Write();
                             });
    return;
  }
  // A client that was far behind leaves large buffers; give the memory back once it caught up.
  if (out_.capacity() > (256u << 10)) std::string().swap(out_);
  if (pending_.capacity() > (256u << 10)) std::string().swap(pending_);
}

void SocketServer::Publish(const nlohmann::json& event) {
  const std::string kind = event.value("class", "");
  std::string line;
  const bool pose_event = kind.rfind("POSE_", 0) == 0;
  const std::string device = event.value("device", "");
  const int index = event.value("index", -1);
  auto sessions = sessions_;  // a send may close a session, which leaves the map
  for (auto& [id, s] : sessions) {
    bool send = s->watch && s->watch->events &&
                (s->watch->device.empty() || device.empty() || s->watch->device == device);
    bool answers = false;
    if (pose_event) {
      auto it = s->pending_poses.find(index);
      if (it != s->pending_poses.end() && it->second.count(device)) {
        send = true;
        if (kind == "POSE_CAPTURED" || kind == "POSE_REJECTED") {
          it->second.erase(device);
          if (it->second.empty()) s->pending_poses.erase(it);
          answers = true;
        }
      }
    }
    if (!send) continue;
    if (line.empty()) line = event.dump() + "\n";
    if (answers) {
      s->Reply(event);  // the answer to a pose is never dropped
    } else {
      s->Stream(line);
    }
  }
}

nlohmann::json ClientSession::Watch(const nlohmann::json& request) {
  std::optional<WatchSpec> spec;
  std::string error;
  if (!protocol::ParseWatchRequest(request, &spec, &error)) return protocol::ErrorMessage(error);
  if (!spec) {
    watch.reset();
    return {{"class", "WATCH"}, {"enable", false}};
  }
  const WatchSpec& w = *spec;
  watch = w;
  last_sample_ns.clear();
  return {{"class", "WATCH"},   {"enable", true},
          {"events", w.events}, {"corrected", w.corrected},
          {"raw", w.raw},       {"uncertainty", w.uncertainty},
          {"device", w.device}, {"max_rate_hz", w.max_rate_hz}};
}

}  // namespace turncal::daemon
