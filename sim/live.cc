#include "sim/live.h"

#include <fcntl.h>
#include <fmt/format.h>
#include <poll.h>
#include <stdlib.h>
#include <sys/ioctl.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/un.h>
#include <termios.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <memory>
#include <random>
#include <set>

#include "core/frames/units.h"
#include "protocol/pose_json.h"
#include "sim/device.h"

namespace turncal::sim {

namespace {

// What a device holds back while nobody reads: one wall-clock second of its stream at the
// session's speed, at least 64 KiB (a serial port's kernel buffer, about 1.8 s of a MIP stream
// at 500 Hz and 1x). Sized in wall time because the simulator's own process can stall: it then
// writes the frames it owes at once, which a real device would have sent over that time. Bytes
// beyond it are dropped and counted, as when the daemon is down.
constexpr std::size_t kMinQueued = 64 * 1024;
constexpr double kQueuedWallS = 1.0;

struct Device {
  std::string path;
  int fd = -1;
  int slave_fd = -1;  // ours, kept open so the pty never hangs up while the daemon restarts
  bool linked = false;
  const SimCapture* capture = nullptr;
  drivers::Protocol protocol = drivers::Protocol::kMip;
  double period_s = 0.01;
  double speed = 1.0;          // session seconds per wall second
  std::size_t max_queued = 0;  // bytes (kMinQueued, kQueuedWallS), set at the first frame
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
  std::uint64_t episode_dropped = 0;  // frames dropped since the daemon last kept up
  double episode_from_s = 0;          // session time of the episode's first dropped frame
  std::chrono::steady_clock::time_point written_at;  // the pty last took bytes
  double episode_blocked_s = 0;   // wall seconds the pty had taken nothing when dropping began
  double episode_loop_gap_s = 0;  // wall seconds the simulator had not run when it began
  // Faults.
  std::uint64_t written = 0, flipped = 0, lost_unplugged = 0, unplugged_frames = 0, unplugs = 0;
  std::uint64_t bits_to_flip = 0;  // clean bits before the next flipped one
  std::mt19937_64 fault_rng;       // the line's channel (BitErrors)
  bool unplugged = false;
  double replug_vt = 0;
};

// One event of the session's log, a JSON line on standard output.
void Say(const nlohmann::json& j) {
  std::fputs((j.dump() + "\n").c_str(), stdout);
  std::fflush(stdout);
}

// A run of dropped frames, for the log: when, for how long, how much, and how long the pty had
// taken nothing and the simulator had not run when it began (equal: the simulator stalled).
void SayDropped(const Device& d, double vt) {
  Say({{"event", "dropped"},
       {"device", d.path},
       {"at_s", d.episode_from_s},
       {"for_s", vt - d.episode_from_s},
       {"pty_full_wall_s", d.episode_blocked_s},
       {"turn_gap_wall_s", d.episode_loop_gap_s},
       {"frames", d.episode_dropped}});
}

// The binary symmetric channel of each device's line: flips the bits it sends (appended to
// d->out) at `rate`. Every line has its own channel, seeded from the session's fault seed and
// the device's place, so where a device's bits flip depends on its own bytes only, not on how
// its bytes and the other devices' interleave in time (which a loaded machine changes).
class BitErrors {
 public:
  explicit BitErrors(double rate) : rate_(rate) {}
  bool on() const { return rate_ > 0; }
  void Start(Device* d, std::uint64_t seed, std::size_t index) const {
    std::seed_seq seq{static_cast<std::uint32_t>(seed), static_cast<std::uint32_t>(seed >> 32),
                      static_cast<std::uint32_t>(index)};
    d->fault_rng.seed(seq);
    d->bits_to_flip = on() ? Gap(d) : 0;
  }
  void Apply(Device* d, std::size_t from) const {
    if (!on()) return;
    const std::uint64_t bits = 8 * static_cast<std::uint64_t>(d->out.size() - from);
    std::uint64_t at = 0;
    while (d->bits_to_flip < bits - at) {
      const std::uint64_t bit = at + d->bits_to_flip;
      d->out[from + bit / 8] = static_cast<char>(d->out[from + bit / 8] ^ (1u << (bit % 8)));
      ++d->flipped;
      at = bit + 1;
      d->bits_to_flip = Gap(d);
    }
    d->bits_to_flip -= bits - at;
  }

 private:
  std::uint64_t Gap(Device* d) const {
    return std::geometric_distribution<std::uint64_t>(rate_)(d->fault_rng);
  }
  double rate_;
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

// The device's dialogue state as at power-up: the i-th simulated device's identity.
std::unique_ptr<DeviceEmulator> PowerUp(const Device& d, std::size_t i,
                                        const LiveSimOptions& options) {
  const std::string& state_dir = options.device_state_dir;
  EmulatedIdentity id;
  id.serial = fmt::format("SIM{:04}", i + 1);
  if (!state_dir.empty() && d.protocol == drivers::Protocol::kMip) {
    id.mip_nonvolatile_path =
        (std::filesystem::path(state_dir) / (id.serial + ".nvm.json")).string();
  }
  id.xbus_device_id = 0x03700001u + static_cast<std::uint32_t>(i);
  if (i < options.serials.size()) {
    id.serial = options.serials[i];
    // Checked by `turncal sim` (8 hex digits for an Xbus device).
    if (d.protocol == drivers::Protocol::kXbus) {
      id.xbus_device_id = static_cast<std::uint32_t>(std::stoul(id.serial, nullptr, 16));
    }
  }
  return DeviceEmulator::Make(d.protocol, id, d.capture->session_options.rate_hz);
}

void Flush(Device* d) {
  if (d->unplugged) return;
  while (!d->out.empty()) {
    const ssize_t n = ::write(d->fd, d->out.data(), d->out.size());
    if (n <= 0) return;  // EAGAIN: nobody reads; the rest waits (bounded by max_queued)
    d->out.erase(0, static_cast<std::size_t>(n));
    d->written += static_cast<std::uint64_t>(n);
    d->written_at = std::chrono::steady_clock::now();
  }
}

// `vt`: session time now; `turn_gap_s`: wall seconds since the simulator's previous turn.
void Emit(Device* d, Sample s, const BitErrors* errors, double vt, double turn_gap_s) {
  if (s.t_device_s) d->last_device_s = *s.t_device_s;
  if (s.counter) d->last_counter = *s.counter;
  if (d->unplugged) {
    ++d->unplugged_frames;
    return;
  }
  if (!d->emulator->streaming()) {
    ++d->withheld;  // idle or in config state: the device sends nothing
    return;
  }
  d->emulator->ApplyStored(&s);  // the stored calibration the host left in use
  const std::vector<std::uint8_t> frame = EncodeSimSample(d->protocol, s);
  if (d->max_queued == 0) {
    d->max_queued =
        std::max(kMinQueued, static_cast<std::size_t>(static_cast<double>(frame.size()) /
                                                      d->period_s * d->speed * kQueuedWallS));
  }
  if (d->out.size() + frame.size() > d->max_queued) {
    ++d->dropped;  // nobody has read for a while (the daemon is down): the bytes are lost
    if (d->episode_dropped++ == 0) {
      d->episode_from_s = vt;
      d->episode_blocked_s =
          std::chrono::duration<double>(std::chrono::steady_clock::now() - d->written_at).count();
      d->episode_loop_gap_s = turn_gap_s;
    }
    return;
  }
  if (d->episode_dropped > 0) {
    SayDropped(*d, vt);  // the daemon reads again
    d->episode_dropped = 0;
  }
  const std::size_t from = d->out.size();
  d->out.append(frame.begin(), frame.end());
  errors->Apply(d, from);
  ++d->sent;
}

// The device goes away: its pty is closed and its link removed; what it had queued is lost.
void Unplug(Device* d, double replug_vt) {
  d->lost_unplugged += d->out.size();
  d->out.clear();
  if (d->slave_fd >= 0) ::close(d->slave_fd);
  if (d->fd >= 0) ::close(d->fd);
  d->fd = d->slave_fd = -1;
  if (d->linked) ::unlink(d->path.c_str());
  d->unplugged = true;
  d->replug_vt = replug_vt;
  ++d->unplugs;
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
    d.speed = options.speed;
    d.emulator = PowerUp(d, i, options);
    if (!d.emulator->storage_error().empty()) {
      Say({{"event", "device_storage"},
           {"device", d.path},
           {"error", d.emulator->storage_error()}});
    }
    if (!OpenDevice(&d, error)) return false;
  }
  const BitErrors errors(options.bit_error_rate);
  for (std::size_t i = 0; i < devices.size(); ++i) errors.Start(&devices[i], options.fault_seed, i);
  for (const auto& u : options.unplugs) {
    if (u.device < 0 || static_cast<std::size_t>(u.device) >= devices.size()) {
      *error = fmt::format("unplug: there is no device {} (0 to {})", u.device, devices.size() - 1);
      return false;
    }
  }
  std::vector<bool> unplug_done(options.unplugs.size(), false);
  auto unplug = [&](std::size_t k, double vt) {
    const auto& u = options.unplugs[k];
    unplug_done[k] = true;
    Device& d = devices[static_cast<std::size_t>(u.device)];
    if (d.unplugged) return;
    Unplug(&d, vt + options.unplug_s);
    Say({{"event", "unplugged"},
         {"device", d.path},
         {"pose", u.pose},
         {"where", u.mid ? "mid-pose" : "between poses"},
         {"replug_in_s", options.unplug_s}});
  };
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
  std::set<std::string> skipped_by;     // devices the daemon left out (not streaming): again later
  int outstanding = 0;                  // pose requests not yet accepted or refused
  bool accepted_any = false;            // some device took this announcement
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
    for (std::size_t k = 0; k < options.unplugs.size(); ++k) {
      if (!unplug_done[k] && !options.unplugs[k].mid &&
          options.unplugs[k].pose == static_cast<int>(p)) {
        unplug(k, vt);
      }
    }
    if (holding) shift_past_hold(vt);
    holding = false;
    announced = false;
    waiting.clear();
    rejected_by.clear();
    skipped_by.clear();
    retry_devices.clear();
    retries_left = options.retries;
    ++p;
  };

  std::vector<bool> lose_left(options.lose_replies.size(), true);  // replies still to lose
  bool end_holding = false;  // after the last pose (hold_end_s)
  double end_hold_until_s = 0;
  auto last_turn = Clock::now();
  auto due_since = Clock::time_point::max();  // pose p could be announced since then (max: not)
  for (;;) {
    const double vt = vt_now();
    const double turn_gap_s = std::chrono::duration<double>(Clock::now() - last_turn).count();
    last_turn = Clock::now();
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
        skipped_by.clear();
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
        const bool ours = announced && m.value("index", -1) == static_cast<int>(p);
        if (kind == "POSE_ACCEPTED" && ours) {
          --outstanding;
          accepted_any = true;
          for (const auto& name : m["devices"]) waiting.insert(name.get<std::string>());
          // A device not streaming at the announcement (reconnecting, configuring) is left out:
          // the pose goes to it again once the others have answered.
          if (m.contains("skipped") && m["skipped"].is_object()) {
            for (const auto& [name, state] : m["skipped"].items()) {
              if (state.is_string() && state.get<std::string>().rfind("replays", 0) != 0) {
                skipped_by.insert(name);
              }
            }
          }
        } else if ((kind == "POSE_CAPTURED" || kind == "POSE_REJECTED") && ours) {
          const std::string device = m.value("device", "");
          waiting.erase(device);
          if (kind == "POSE_REJECTED") rejected_by.insert(device);
          Say({{"event", "answer"},
               {"index", p},
               {"device", device},
               {"class", kind},
               {"saved", m.value("saved", false)},
               {"reason", m.value("reason", "")}});
        } else if (kind == "ERROR" && announced && outstanding > 0) {
          // A pose request refused (e.g. its device is not streaming): that device again later.
          // A retry to one device carries the device's name as its id.
          --outstanding;
          Say({{"event", "refused"}, {"index", p}, {"message", m.value("message", "")}});
          if (m.contains("id") && m["id"].is_string())
            skipped_by.insert(m["id"].get<std::string>());
        } else {
          continue;
        }
        if (outstanding > 0 || !waiting.empty()) continue;
        // Every request of this announcement answered.
        if (!accepted_any) {
          // Refused outright (no device streaming yet): the same again in a moment.
          announced = false;
          retry_at = Clock::now() + std::chrono::milliseconds(500);
        } else if (rejected_by.empty() && skipped_by.empty()) {
          ++report->captured;
          end_hold(vt);
        } else if (retries_left-- > 0) {
          // Once more (the table holds still), to the devices that rejected it or were left out,
          // after a moment: what interrupted the stream may not be over yet.
          announced = false;
          retry_at = Clock::now() + std::chrono::milliseconds(250);
          retry_devices = rejected_by;
          retry_devices.insert(skipped_by.begin(), skipped_by.end());
        } else {
          ++report->unanswered;
          end_hold(vt);
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
    // The daemon's timeouts run on the wall clock whatever the speed: so does the table's wait.
    auto held_wall_s = [&] { return (vt - hold_start_s) / options.speed; };
    if (start_holding && start_rest && held_wall_s() > options.answer_timeout_s) {
      Say({{"event", "start_rest"}, {"state", "gave up waiting for the noise"}, {"after_s", vt}});
      start_rest = false;
    }
    if (start_holding && !start_rest) {
      start_holding = false;
      shift_past_hold(vt);
    }
    // The table holds while the pose is not answered.
    if (p < events.size() && !holding && !start_holding && vt >= events[p].dwell_end_s + shift_s) {
      holding = true;
      begin_hold(events[p].t_s, events[p].dwell_end_s, events[p].dwell_end_s + shift_s);
    }
    if (holding && held_wall_s() > options.answer_timeout_s) {
      Say({{"event", "gave_up"}, {"index", p}, {"after_s", vt - hold_start_s}});
      ++report->unanswered;
      end_hold(vt);
    }
    // Unplugs halfway through a pose's dwell (announced, not yet answered); replugs.
    for (std::size_t k = 0; k < options.unplugs.size(); ++k) {
      if (!unplug_done[k] && options.unplugs[k].mid &&
          options.unplugs[k].pose == static_cast<int>(p) && p < events.size() && announced &&
          vt >= 0.5 * (events[p].t_s + events[p].dwell_end_s) + shift_s) {
        unplug(k, vt);
      }
    }
    for (std::size_t i = 0; i < devices.size(); ++i) {
      Device& d = devices[i];
      if (!d.unplugged || vt < d.replug_vt) continue;
      if (!OpenDevice(&d, error)) return false;
      d.emulator = PowerUp(d, i, options);
      d.unplugged = false;
      Say({{"event", "replugged"}, {"device", d.path}});
    }
    // The devices stream.
    bool done = p >= events.size();
    for (Device& d : devices) {
      const auto& samples = d.capture->session.samples;
      if (holding || start_holding || end_holding) {
        while (d.clone_due_s <= vt && !d.hold_samples.empty()) {
          const std::size_t n = d.hold_samples.size();
          const std::size_t at = d.clones % (2 * n);
          Sample s = samples[d.hold_samples[at < n ? at : 2 * n - 1 - at]];
          s.t_device_s = d.last_device_s + d.period_s;
          if (s.counter) s.counter = d.last_counter + 1;
          Emit(&d, s, &errors, vt, turn_gap_s);
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
          Emit(&d, s, &errors, vt, turn_gap_s);
        }
      }
      done = done && d.next >= samples.size();
      Flush(&d);
    }
    // Announce the pose once the table has settled there, after the samples sent before (they
    // are in the ptys unless the daemon has not read for a while; then after at most 0.5 s).
    bool flushed = true;
    for (const Device& d : devices) flushed = flushed && d.out.empty();
    const bool due = p < events.size() && !announced && !start_holding && controller.connected() &&
                     Clock::now() >= retry_at && vt >= events[p].t_s + shift_s;
    if (!due) {
      due_since = Clock::time_point::max();
    } else if (due_since == Clock::time_point::max()) {
      due_since = Clock::now();
    }
    if (due && (flushed || Clock::now() - due_since >= std::chrono::milliseconds(500))) {
      due_since = Clock::time_point::max();
      const TablePose& pose = events[p].pose;
      nlohmann::json request = {{"cmd", "pose"},
                                {"index", p},
                                {"phi_deg", pose.phi_rad * kDegPerRad},
                                {"gamma_deg", pose.gamma_rad * kDegPerRad},
                                {"psi_deg", pose.psi_rad * kDegPerRad}};
      if (pose.is_rate()) {
        // A rate segment: the table turns about one axis (docs/protocol.md "rate"); whole
        // revolutions of at least the session's dwell, as the simulator holds the rate.
        request = protocol::ToJson(pose);
        request["cmd"] = "rate";
        request["axis"] = request["rate_axis"];
        request.erase("rate_axis");
        request["index"] = p;
        request["dwell_s"] = devices[0].capture->session_options.dwell_s;
      }
      bool sent = true;
      outstanding = 0;
      if (retry_devices.empty()) {
        sent = controller.Send(request);
        outstanding = 1;
      } else {
        for (const auto& device : retry_devices) {
          nlohmann::json one = request;
          one["device"] = device;
          one["id"] = device;
          sent = sent && controller.Send(one);
          ++outstanding;
        }
      }
      if (sent) {
        announced = true;
        accepted_any = false;
        waiting.clear();
        rejected_by.clear();
        skipped_by.clear();
        nlohmann::json said = protocol::ToJson(pose);
        said["event"] = pose.is_rate() ? "rate" : "pose";
        said["index"] = p;
        Say(said);
      }
    }
    if (done && options.hold_end_s > 0 && !end_holding && !events.empty()) {
      end_holding = true;
      end_hold_until_s = vt + options.hold_end_s;
      begin_hold(events.back().t_s, events.back().dwell_end_s, vt);
      Say({{"event", "holding_end"}, {"index", events.size() - 1}, {"for_s", options.hold_end_s}});
    }
    if (done && (!end_holding || vt >= end_hold_until_s)) break;
    // Wait for the device's commands (or 1 ms).
    std::vector<pollfd> fds;
    for (const Device& d : devices) fds.push_back({d.fd, POLLIN, 0});  // fd -1: ignored
    ::poll(fds.data(), fds.size(), 1);
    for (std::size_t i = 0; i < devices.size(); ++i) {
      if (!(fds[i].revents & POLLIN)) continue;
      std::uint8_t buffer[4096];
      if (devices[i].fd < 0) continue;
      const ssize_t n = ::read(devices[i].fd, buffer, sizeof(buffer));
      if (n <= 0) continue;
      const auto reply = devices[i].emulator->OnHostBytes({buffer, static_cast<std::size_t>(n)});
      // A command whose reply is to be lost (a 3DM command in one read: the daemon writes each
      // command whole): carried out, the reply dropped, once.
      bool lost = false;
      for (std::size_t k = 0; k < lose_left.size() && !lost; ++k) {
        const auto& l = options.lose_replies[k];
        for (ssize_t at = 0; lose_left[k] && at + 6 < n; ++at) {
          if (buffer[at] == 0x75 && buffer[at + 1] == 0x65 && buffer[at + 2] == 0x0C &&
              buffer[at + 5] == l.descriptor && buffer[at + 6] == l.function) {
            lose_left[k] = false;
            lost = true;
            Say({{"event", "reply_lost"},
                 {"device", devices[i].path},
                 {"command", fmt::format("0x0C 0x{:02X} function {}", l.descriptor, l.function)},
                 {"reply_bytes", reply.size()}});
            break;
          }
        }
      }
      if (lost) continue;
      const std::size_t from = devices[i].out.size();
      devices[i].out.append(reply.begin(), reply.end());
      errors.Apply(&devices[i], from);
      Flush(&devices[i]);
    }
  }
  // Before the ptys close (closing discards what the daemon has not read): wait until every
  // queued byte is written and the slave side has held nothing for 100 ms, up to 5 s. One empty
  // look is not enough: a pty hands what the master wrote to the slave's line discipline from a
  // kernel work queue, so FIONREAD can read 0 just after a write, before the bytes arrive.
  int quiet_ms = 0;
  for (int waited_ms = 0; waited_ms < 5000 && quiet_ms < 100; waited_ms += 10) {
    bool quiet = true;
    for (Device& d : devices) {
      const std::uint64_t before = d.written;
      Flush(&d);
      int unread = 0;
      if (d.slave_fd >= 0 && ::ioctl(d.slave_fd, FIONREAD, &unread) == 0 && unread > 0) {
        quiet = false;
      }
      quiet = quiet && d.written == before && (d.out.empty() || d.fd < 0);
    }
    quiet_ms = quiet ? quiet_ms + 10 : 0;
    ::usleep(10'000);
  }
  for (std::size_t i = 0; i < devices.size(); ++i) {
    if (devices[i].episode_dropped > 0) {  // still dropping when the session ended
      SayDropped(devices[i], vt_now());
    }
    report->frames_sent[i] = devices[i].sent;
    report->frames_withheld[i] = devices[i].withheld;
    report->frames_dropped[i] = devices[i].dropped;
    report->bytes_written.push_back(devices[i].written);
    report->bits_flipped.push_back(devices[i].flipped);
    report->bytes_lost_unplugged.push_back(devices[i].lost_unplugged);
    report->frames_unplugged.push_back(devices[i].unplugged_frames);
    report->unplugs.push_back(devices[i].unplugs);
    if (devices[i].slave_fd >= 0) ::close(devices[i].slave_fd);
    if (devices[i].fd >= 0) ::close(devices[i].fd);
    if (devices[i].linked) ::unlink(devices[i].path.c_str());
  }
  return true;
}

}  // namespace turncal::sim
