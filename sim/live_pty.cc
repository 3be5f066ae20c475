#include "sim/live_pty.h"

#include <fcntl.h>
#include <fmt/format.h>
#include <stdlib.h>
#include <sys/stat.h>
#include <termios.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>

namespace turncal::sim::live {

namespace {

// What a device holds back while nobody reads: one wall-clock second of its stream at the
// session's speed, at least 64 KiB (a serial port's kernel buffer, about 1.8 s of a MIP stream
// at 500 Hz and 1x). Sized in wall time because the simulator's own process can stall: it then
// writes the frames it owes at once, which a real device would have sent over that time. Bytes
// beyond it are dropped and counted, as when the daemon is down.
constexpr std::size_t kMinQueued = 64 * 1024;
constexpr double kQueuedWallS = 1.0;

}  // namespace

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

void BitErrors::Start(Device* d, std::uint64_t seed, std::size_t index) const {
  std::seed_seq seq{static_cast<std::uint32_t>(seed), static_cast<std::uint32_t>(seed >> 32),
                    static_cast<std::uint32_t>(index)};
  d->fault_rng.seed(seq);
  d->bits_to_flip = on() ? Gap(d) : 0;
}

void BitErrors::Apply(Device* d, std::size_t from) const {
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

std::uint64_t BitErrors::Gap(Device* d) const {
  return std::geometric_distribution<std::uint64_t>(rate_)(d->fault_rng);
}

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

void Close(Device* d) {
  if (d->slave_fd >= 0) ::close(d->slave_fd);
  if (d->fd >= 0) ::close(d->fd);
  if (d->linked) ::unlink(d->path.c_str());
}

}  // namespace turncal::sim::live
