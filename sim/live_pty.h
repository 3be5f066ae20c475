#pragma once
// The pieces of `turncal sim --live` (sim/live.h) below the session: one simulated device's line
// -- its pseudo-terminal, the bytes it holds back while nobody reads, the faults on it -- and
// the session's log on standard output. For sim/live.cc only.

#include <chrono>
#include <cstdint>
#include <memory>
#include <nlohmann/json.hpp>
#include <random>
#include <string>
#include <vector>

#include "sim/capture.h"
#include "sim/device.h"
#include "sim/live.h"

namespace turncal::sim::live {

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
void Say(const nlohmann::json& j);

// A run of dropped frames, for the log: when, for how long, how much, and how long the pty had
// taken nothing and the simulator had not run when it began (equal: the simulator stalled).
void SayDropped(const Device& d, double vt);

// The binary symmetric channel of each device's line: flips the bits it sends (appended to
// d->out) at `rate`. Every line has its own channel, seeded from the session's fault seed and
// the device's place, so where a device's bits flip depends on its own bytes only, not on how
// its bytes and the other devices' interleave in time (which a loaded machine changes).
class BitErrors {
 public:
  explicit BitErrors(double rate) : rate_(rate) {}
  bool on() const { return rate_ > 0; }
  void Start(Device* d, std::uint64_t seed, std::size_t index) const;
  void Apply(Device* d, std::size_t from) const;

 private:
  std::uint64_t Gap(Device* d) const;
  double rate_;
};

// Opens the device's existing tty, or creates a pseudo-terminal linked at its path; raw, no echo.
bool OpenDevice(Device* d, std::string* error);

// The device's dialogue state as at power-up: the i-th simulated device's identity.
std::unique_ptr<DeviceEmulator> PowerUp(const Device& d, std::size_t i,
                                        const LiveSimOptions& options);

// Writes what the pty takes of the device's queue.
void Flush(Device* d);

// Queues one sample's frame as the device's emulator sends it (or counts it withheld or
// dropped). `vt`: session time now; `turn_gap_s`: wall seconds since the simulator's previous
// turn.
void Emit(Device* d, Sample s, const BitErrors* errors, double vt, double turn_gap_s);

// The device goes away: its pty is closed and its link removed; what it had queued is lost.
void Unplug(Device* d, double replug_vt);

// The device's pty closed and its link removed, at the session's end.
void Close(Device* d);

}  // namespace turncal::sim::live
