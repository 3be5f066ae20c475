#include "tools/sim_live.h"

#include <fcntl.h>
#include <fmt/format.h>
#include <poll.h>
#include <stdlib.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/un.h>
#include <termios.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstring>
#include <memory>
#include <set>

#include "tools/sim_device.h"

namespace turncal::tools {

namespace {

constexpr std::size_t kMaxQueued = 64 * 1024;  // bytes a device holds back when nobody reads

struct Device {
  std::string path;
  int fd = -1;
  int slave_fd = -1;  // ours, kept open so the pty never hangs up while the daemon restarts
  bool linked = false;
  const SimCapture* capture = nullptr;
  drivers::Protocol protocol = drivers::Protocol::kMip;
  double period_s = 0.01;
  std::unique_ptr<DeviceEmulator> emulator;
  std::size_t next = 0;       // next original sample
  double shift_s = 0;         // session-time shift of the original samples (holds so far)
  double device_shift_s = 0;  // the same on the device clock
  std::uint32_t counter_shift = 0;
  std::vector<std::size_t> hold_samples;  // the held pose's stationary samples
  std::size_t clones = 0;
  double clone_due_s = 0;
  double last_device_s = 0;
  std::uint32_t last_counter = 0;
  std::string out;
  std::uint64_t sent = 0, withheld = 0, dropped = 0;
};

bool OpenDevice(Device* d, std::string* error) {
  struct stat st {};
  if (::lstat(d->path.c_str(), &st) == 0 && S_ISCHR(st.st_mode)) {
    d->fd = ::open(d->path.c_str(), O_RDWR | O_NOCTTY | O_NONBLOCK | O_CLOEXEC);
    if (d->fd < 0) {
      *error = fmt::format("cannot open '{}': {}", d->path, std::strerror(errno));
      return false;
    }
  } else {
    if (::lstat(d->path.c_str(), &st) == 0 && !S_ISLNK(st.st_mode)) {
      *error = fmt::format("'{}' exists and is not a tty or a symlink", d->path);
      return false;
    }
    d->fd = ::posix_openpt(O_RDWR | O_NOCTTY | O_NONBLOCK | O_CLOEXEC);
    if (d->fd < 0 || ::grantpt(d->fd) != 0 || ::unlockpt(d->fd) != 0) {
      *error = fmt::format("cannot create a pseudo-terminal: {}", std::strerror(errno));
      return false;
    }
    const char* slave = ::ptsname(d->fd);
    d->slave_fd = ::open(slave, O_RDWR | O_NOCTTY | O_NONBLOCK | O_CLOEXEC);
    ::unlink(d->path.c_str());
    if (d->slave_fd < 0 || ::symlink(slave, d->path.c_str()) != 0) {
      *error = fmt::format("cannot link '{}' to {}: {}", d->path, slave, std::strerror(errno));
      return false;
    }
    d->linked = true;
  }
  // Raw, no echo: the daemon's commands must not come back to it.
  termios t{};
  const int tty = d->slave_fd >= 0 ? d->slave_fd : d->fd;
  if (::tcgetattr(tty, &t) == 0) {
    ::cfmakeraw(&t);
    ::tcsetattr(tty, TCSANOW, &t);
  }
  return true;
}

void Flush(Device* d) {
  while (!d->out.empty()) {
    const ssize_t n = ::write(d->fd, d->out.data(), d->out.size());
    if (n <= 0) return;  // EAGAIN: nobody reads; the rest waits (bounded by kMaxQueued)
    d->out.erase(0, static_cast<std::size_t>(n));
  }
}

void Emit(Device* d, Sample s) {
  if (s.t_device_s) d->last_device_s = *s.t_device_s;
  if (s.counter) d->last_counter = *s.counter;
  if (!d->emulator->streaming()) {
    ++d->withheld;  // idle or in config state: the device sends nothing
    return;
  }
  const std::vector<std::uint8_t> frame = EncodeSimSample(d->protocol, s);
  if (d->out.size() + frame.size() > kMaxQueued) {
    ++d->dropped;  // nobody has read for a while (the daemon is down): the bytes are lost
    return;
  }
  d->out.append(frame.begin(), frame.end());
  ++d->sent;
}

class Controller {
 public:
  explicit Controller(std::string path) : path_(std::move(path)) {}
  ~Controller() { Close(); }
  bool connected() const { return fd_ >= 0; }
  int fd() const { return fd_; }
  bool TryConnect() {
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
  void Close() {
    if (fd_ >= 0) ::close(fd_);
    fd_ = -1;
  }
  bool Send(const nlohmann::json& j) {
    const std::string text = j.dump() + "\n";
    const ssize_t n = ::send(fd_, text.data(), text.size(), MSG_NOSIGNAL);
    if (n != static_cast<ssize_t>(text.size())) {
      Close();
      return false;
    }
    return true;
  }
  // Reads what arrived; false when the daemon closed the connection.
  bool Read(std::vector<nlohmann::json>* messages) {
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

 private:
  std::string path_;
  int fd_ = -1;
  std::string buffer_;
};

void Say(const nlohmann::json& j) {
  std::fputs((j.dump() + "\n").c_str(), stdout);
  std::fflush(stdout);
}

constexpr double kRadToDeg = 180.0 / M_PI;

}  // namespace

bool RunLiveSim(std::vector<LiveSimDevice>* sims, const LiveSimOptions& options,
                LiveSimReport* report, std::string* error) {
  *report = LiveSimReport{};
  if (sims->empty() || options.controller.empty()) {
    *error = "the live controller needs at least one device and the daemon's socket";
    return false;
  }
  std::vector<Device> devices(sims->size());
  for (std::size_t i = 0; i < sims->size(); ++i) {
    Device& d = devices[i];
    d.path = (*sims)[i].path;
    d.capture = &(*sims)[i].capture;
    d.protocol = d.capture->header.devices.at(0).protocol;
    d.period_s = 1.0 / d.capture->session_options.rate_hz;
    EmulatedIdentity id;
    id.serial = fmt::format("SIM{:04}", i + 1);
    id.xbus_device_id = 0x03700001u + static_cast<std::uint32_t>(i);
    d.emulator = DeviceEmulator::Make(d.protocol, id, d.capture->session_options.rate_hz);
    if (!OpenDevice(&d, error)) return false;
  }
  const auto& events = devices[0].capture->session.events;
  report->poses = static_cast<int>(events.size());
  report->frames_sent.assign(devices.size(), 0);
  report->frames_withheld.assign(devices.size(), 0);
  report->frames_dropped.assign(devices.size(), 0);

  Controller controller(options.controller);
  using Clock = std::chrono::steady_clock;
  const auto start = Clock::now();
  auto vt_now = [&] {
    return std::chrono::duration<double>(Clock::now() - start).count() * options.speed;
  };
  auto last_connect_try = start - std::chrono::seconds(1);
  auto disconnected_since = start;
  bool ever_connected = false;

  std::size_t p = 0;       // the pose the table is at (or moving to)
  double shift_s = 0;      // session seconds of holds so far
  bool announced = false;  // pose p announced and not yet fully answered
  std::set<std::string> waiting, rejected_by;
  std::set<std::string> retry_devices;  // a retry goes to these only (empty: every device)
  int retries_left = options.retries;
  bool holding = false;
  double hold_start_s = 0;
  auto retry_at = start;
  // The table rests at home until the daemon has measured every device's noise (a real
  // controller waits for NOISE_MEASURED before it moves the table the first time).
  bool start_rest = !events.empty();
  bool start_holding = false;
  auto status_at = start;
  const double start_s = devices[0].capture->session_options.start_s;
  // The samples of [t0, t1) are streamed again (forwards, then backwards: no step at the seams).
  auto begin_hold = [&](double t0_s, double t1_s, double at_vt) {
    for (Device& d : devices) {
      d.hold_samples.clear();
      const auto& samples = d.capture->session.samples;
      for (std::size_t k = 0; k < samples.size(); ++k) {
        const double t = static_cast<double>(samples[k].t_host_ns) * 1e-9;
        if (t >= t0_s && t < t1_s) d.hold_samples.push_back(k);
      }
      d.clones = 0;
      d.clone_due_s = at_vt;
    }
    hold_start_s = at_vt;
  };
  auto shift_past_hold = [&](double vt) {
    for (Device& d : devices) {
      d.shift_s += static_cast<double>(d.clones) * d.period_s;
      d.device_shift_s += static_cast<double>(d.clones) * d.period_s;
      d.counter_shift += static_cast<std::uint32_t>(d.clones);
      d.clones = 0;
    }
    report->held_s += vt - hold_start_s;
    shift_s += vt - hold_start_s;
  };

  auto end_hold = [&](double vt) {
    if (holding) shift_past_hold(vt);
    holding = false;
    announced = false;
    waiting.clear();
    rejected_by.clear();
    retry_devices.clear();
    retries_left = options.retries;
    ++p;
  };

  for (;;) {
    const double vt = vt_now();
    // The daemon's socket: (re)connect.
    if (!controller.connected() &&
        Clock::now() - last_connect_try > std::chrono::milliseconds(200)) {
      last_connect_try = Clock::now();
      if (controller.TryConnect()) {
        if (ever_connected) ++report->reconnects;
        ever_connected = true;
        Say({{"event", "controller"}, {"state", "connected"}, {"socket", options.controller}});
      } else if (std::chrono::duration<double>(Clock::now() - disconnected_since).count() >
                 options.connect_timeout_s) {
        *error = fmt::format("no turncald answered on {} for {} s", options.controller,
                             options.connect_timeout_s);
        return false;
      }
    }
    if (controller.connected()) {
      std::vector<nlohmann::json> messages;
      if (!controller.Read(&messages)) {
        Say({{"event", "controller"}, {"state", "disconnected"}});
        disconnected_since = Clock::now();
        announced = false;  // announced again once the daemon is back
        waiting.clear();
        rejected_by.clear();
      }
      for (const auto& m : messages) {
        const std::string kind = m.value("class", "");
        if (kind == "STATUS" && start_rest && m.contains("devices") && m["devices"].is_object() &&
            !m["devices"].empty()) {
          bool measured = true;
          for (const auto& [name, dev] : m["devices"].items()) {
            measured = measured && dev.contains("station") && dev["station"].is_object() &&
                       dev["station"].value("noise", "") == "measured";
          }
          if (measured) {
            start_rest = false;
            Say({{"event", "start_rest"}, {"state", "noise measured"}, {"after_s", vt}});
          }
        }
        if (kind == "POSE_ACCEPTED" && m.value("index", -1) == static_cast<int>(p) && announced) {
          for (const auto& name : m["devices"]) waiting.insert(name.get<std::string>());
        } else if ((kind == "POSE_CAPTURED" || kind == "POSE_REJECTED") &&
                   m.value("index", -1) == static_cast<int>(p) && announced) {
          const std::string device = m.value("device", "");
          waiting.erase(device);
          if (kind == "POSE_REJECTED") rejected_by.insert(device);
          Say({{"event", "answer"},
               {"index", p},
               {"device", device},
               {"class", kind},
               {"reason", m.value("reason", "")}});
          if (waiting.empty()) {
            if (rejected_by.empty()) {
              ++report->captured;
              end_hold(vt);
            } else if (retries_left-- > 0) {
              // Once more (the table holds still), to the devices that rejected it only.
              announced = false;
              retry_devices = rejected_by;
              rejected_by.clear();
            } else {
              ++report->unanswered;
              end_hold(vt);
            }
          }
        } else if (kind == "ERROR" && announced && waiting.empty()) {
          // Our pose was refused (e.g. no device streaming yet): again in a moment.
          Say({{"event", "refused"}, {"index", p}, {"message", m.value("message", "")}});
          announced = false;
          retry_at = Clock::now() + std::chrono::milliseconds(500);
        }
      }
    }
    // At rest at home: ask the daemon whether every device's noise is measured.
    if (start_rest && controller.connected() && Clock::now() >= status_at) {
      status_at = Clock::now() + std::chrono::milliseconds(250);
      controller.Send({{"cmd", "status"}});
    }
    if (start_rest && !start_holding && vt >= start_s + shift_s) {
      start_holding = true;
      begin_hold(0.0, start_s, start_s + shift_s);
    }
    if (start_holding && start_rest && vt - hold_start_s > options.answer_timeout_s) {
      Say({{"event", "start_rest"}, {"state", "gave up waiting for the noise"}, {"after_s", vt}});
      start_rest = false;
    }
    if (start_holding && !start_rest) {
      start_holding = false;
      shift_past_hold(vt);
    }
    // Announce the pose once the table has settled there.
    if (p < events.size() && !announced && !start_holding && controller.connected() &&
        Clock::now() >= retry_at && vt >= events[p].t_s + shift_s) {
      const TablePose& pose = events[p].pose;
      const nlohmann::json request = {{"cmd", "pose"},
                                      {"index", p},
                                      {"phi_deg", pose.phi_rad * kRadToDeg},
                                      {"gamma_deg", pose.gamma_rad * kRadToDeg},
                                      {"psi_deg", pose.psi_rad * kRadToDeg}};
      bool sent = true;
      if (retry_devices.empty()) {
        sent = controller.Send(request);
      } else {
        for (const auto& device : retry_devices) {
          nlohmann::json one = request;
          one["device"] = device;
          sent = sent && controller.Send(one);
        }
      }
      if (sent) {
        announced = true;
        waiting.clear();
        rejected_by.clear();
        Say({{"event", "pose"},
             {"index", p},
             {"phi_deg", pose.phi_rad * kRadToDeg},
             {"gamma_deg", pose.gamma_rad * kRadToDeg},
             {"psi_deg", pose.psi_rad * kRadToDeg}});
      }
    }
    // The table holds while the pose is not answered.
    if (p < events.size() && !holding && !start_holding && vt >= events[p].dwell_end_s + shift_s) {
      holding = true;
      begin_hold(events[p].t_s, events[p].dwell_end_s, events[p].dwell_end_s + shift_s);
    }
    if (holding && vt - hold_start_s > options.answer_timeout_s) {
      Say({{"event", "gave_up"}, {"index", p}, {"after_s", vt - hold_start_s}});
      ++report->unanswered;
      end_hold(vt);
    }
    // The devices stream.
    bool done = p >= events.size();
    for (Device& d : devices) {
      const auto& samples = d.capture->session.samples;
      if (holding || start_holding) {
        while (d.clone_due_s <= vt && !d.hold_samples.empty()) {
          const std::size_t n = d.hold_samples.size();
          const std::size_t at = d.clones % (2 * n);
          Sample s = samples[d.hold_samples[at < n ? at : 2 * n - 1 - at]];
          s.t_device_s = d.last_device_s + d.period_s;
          if (s.counter) s.counter = d.last_counter + 1;
          Emit(&d, s);
          ++d.clones;
          d.clone_due_s += d.period_s;
        }
      } else {
        while (d.next < samples.size() &&
               static_cast<double>(samples[d.next].t_host_ns) * 1e-9 + d.shift_s <= vt &&
               (p >= events.size() ||
                static_cast<double>(samples[d.next].t_host_ns) * 1e-9 < events[p].dwell_end_s)) {
          Sample s = samples[d.next++];
          if (s.t_device_s) *s.t_device_s += d.device_shift_s;
          if (s.counter) *s.counter += d.counter_shift;
          Emit(&d, s);
        }
      }
      done = done && d.next >= samples.size();
      Flush(&d);
    }
    if (done) break;
    // Wait for the device's commands (or 1 ms).
    std::vector<pollfd> fds;
    for (const Device& d : devices) fds.push_back({d.fd, POLLIN, 0});
    ::poll(fds.data(), fds.size(), 1);
    for (std::size_t i = 0; i < devices.size(); ++i) {
      if (!(fds[i].revents & POLLIN)) continue;
      std::uint8_t buffer[4096];
      const ssize_t n = ::read(devices[i].fd, buffer, sizeof(buffer));
      if (n <= 0) continue;
      const auto reply = devices[i].emulator->OnHostBytes({buffer, static_cast<std::size_t>(n)});
      devices[i].out.append(reply.begin(), reply.end());
      Flush(&devices[i]);
    }
  }
  for (std::size_t i = 0; i < devices.size(); ++i) {
    report->frames_sent[i] = devices[i].sent;
    report->frames_withheld[i] = devices[i].withheld;
    report->frames_dropped[i] = devices[i].dropped;
    if (devices[i].slave_fd >= 0) ::close(devices[i].slave_fd);
    ::close(devices[i].fd);
    if (devices[i].linked) ::unlink(devices[i].path.c_str());
  }
  return true;
}

}  // namespace turncal::tools
