#pragma once
// The socket server (DESIGN.md "Socket protocol"; docs/protocol.md): JSON Lines over a Unix
// stream socket, one session per client on the event loop. Requests longer than
// protocol::kMaxRequestBytes are answered with ERROR and discarded up to their newline. Output to
// a client is queued: stream messages (events, samples) beyond `stream_queue_bytes` are dropped
// and counted (the client is told with DROPPED when it catches up); a client whose replies alone
// pass `max_queue_bytes` is disconnected. Nothing a client does blocks the loop or another client.
//
// Peers are identified with SO_PEERCRED; `control` says whether a peer may send mutating
// commands (root, turncald's own uid, and the configured users).

#include <boost/asio/io_context.hpp>
#include <boost/asio/local/stream_protocol.hpp>
#include <functional>
#include <memory>
#include <nlohmann/json.hpp>
#include <optional>
#include <set>
#include <string>
#include <unordered_map>

#include "protocol/messages.h"

namespace turncal::daemon {

struct SocketOptions {
  std::string path = "/run/turncal/turncal.sock";
  std::string group;                // owner group of the socket (mode 0660); empty: ours
  std::set<unsigned> control_uids;  // besides root and our own uid
  std::size_t stream_queue_bytes = 1 << 20;
  std::size_t max_queue_bytes = 8 << 20;
  std::optional<int> activated_fd;  // a listening socket from systemd (socket activation)
};

// A user name or number -> uid; false with a message.
bool ResolveUser(const std::string& name_or_uid, unsigned* uid, std::string* error);

class ClientSession;

using protocol::WatchSpec;  // what a watching client asked for

class SocketServer {
 public:
  using RequestHandler =
      std::function<void(const std::shared_ptr<ClientSession>&, const nlohmann::json& request)>;
  SocketServer(boost::asio::io_context& io, SocketOptions options, RequestHandler on_request);
  ~SocketServer();

  // Creates (or adopts) the listening socket and starts accepting. False with a message.
  bool Listen(std::string* error);
  void Stop();  // closes the listener and every session; removes the socket file we created

  // Every open session (for broadcasting).
  const std::unordered_map<std::uint64_t, std::shared_ptr<ClientSession>>& sessions() const {
    return sessions_;
  }
  std::uint64_t accepted() const { return accepted_; }
  // An event to every session: to the watchers of events (of its device, or of all), and, for
  // POSE_CAPTURED / POSE_REJECTED, as the answer to the session that announced the pose (never
  // dropped; the pose is then no longer pending there). Other POSE_ events go to the announcer
  // as stream lines.
  void Publish(const nlohmann::json& event);
  // SIGHUP: who may send mutating commands, for connections from now on and open ones alike.
  void SetControlUids(std::set<unsigned> uids);
  bool IsControl(unsigned uid) const;

 private:
  friend class ClientSession;
  void Accept();
  void Remove(std::uint64_t id);

  boost::asio::io_context& io_;
  SocketOptions options_;
  RequestHandler on_request_;
  std::unique_ptr<boost::asio::local::stream_protocol::acceptor> acceptor_;
  std::unordered_map<std::uint64_t, std::shared_ptr<ClientSession>> sessions_;
  std::uint64_t next_id_ = 1;
  std::uint64_t accepted_ = 0;
  bool created_file_ = false;
  bool stopped_ = false;
};

class ClientSession : public std::enable_shared_from_this<ClientSession> {
 public:
  ClientSession(SocketServer* server, boost::asio::local::stream_protocol::socket socket,
                std::uint64_t id);
  void Start();
  void Close();

  // A reply (never dropped; a client that lets replies pile up past the limit is disconnected).
  void Reply(const nlohmann::json& message);
  // A stream message: dropped and counted when the client is behind.
  void Stream(const std::string& line);

  std::uint64_t id() const { return id_; }
  unsigned uid() const { return uid_; }
  int pid() const { return pid_; }
  bool control() const { return known_ && server_->IsControl(uid_); }
  bool open() const { return open_; }
  std::uint64_t dropped_total() const { return dropped_total_; }
  std::size_t queued_bytes() const { return pending_.size(); }

  // A watch request: what this client is streamed from now on (its WATCH reply, or an ERROR).
  nlohmann::json Watch(const nlohmann::json& request);
  std::optional<WatchSpec> watch;
  // The last sample time sent per device (rate limit), host ns.
  std::unordered_map<std::string, std::int64_t> last_sample_ns;
  // Poses this client announced and still waits for: index -> devices not yet answered.
  std::unordered_map<int, std::set<std::string>> pending_poses;

 private:
  void Read();
  void OnBytes(std::size_t n);
  void Enqueue(const std::string& line, bool droppable);
  void Write();

  SocketServer* server_;
  boost::asio::local::stream_protocol::socket socket_;
  std::uint64_t id_;
  unsigned uid_ = 0;
  int pid_ = 0;
  bool known_ = false;  // SO_PEERCRED answered
  bool open_ = true;
  std::array<char, 8192> buffer_{};
  protocol::RequestFramer framer_;
  std::string pending_;        // queued bytes, whole lines, not yet handed to the socket
  bool writing_ = false;       // an asynchronous write is in flight
  bool flush_posted_ = false;  // a Write() is posted to the loop
  std::string out_;            // the bytes being written
  std::uint64_t dropped_ = 0, dropped_total_ = 0;
};

}  // namespace turncal::daemon
