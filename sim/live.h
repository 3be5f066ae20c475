#pragma once
// `turncal sim --live PTY... --controller SOCKET`: the simulator plays the turntable, its sensors
// and the lab's controller against a running turncald. Each simulated device streams its frames
// into a pseudo-terminal at real time (times the speed) and answers the daemon's configuration
// dialogue through the device emulator (sim/device.h), sending no samples while the host
// has it idle or in config state. The controller announces every pose on the daemon's socket
// when the table has settled and -- like a real controller -- holds the table there until every
// device has answered: while it waits past the planned dwell, the devices keep streaming the
// pose's stationary samples again (device time and counters advancing; forwards, then backwards,
// so the bias wander has no step where the loop closes). Before the first move the table rests
// at home, streaming the start's samples the same way, until the daemon's status says every
// device has measured its noise (or `answer_timeout_s` passed), as a controller that waits for
// NOISE_MEASURED would. A rejected pose is
// announced again (up to `retries` times) to the devices that rejected it, and so is a pose to a
// device POSE_ACCEPTED lists as skipped (not streaming). A daemon that goes away (kill -9) is
// reconnected, and the pose it did not answer is announced again.
//
// PTY: a path that does not exist (or is a symlink) gets a new pseudo-terminal, linked there; an
// existing character device (a socat pty, a real serial port) is used as it is.

#include <cstdint>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "sim/capture.h"

namespace turncal::sim {

struct LiveSimDevice {
  std::string path;
  SimCapture capture;
};

struct LiveSimOptions {
  double speed = 1.0;
  std::string controller;         // turncald's socket; empty: pose events on stdout only
  double connect_timeout_s = 60;  // real seconds to wait for the daemon's socket
  double answer_timeout_s = 120;  // wall seconds the table waits for an answer (as the daemon)
  int retries = 2;                // a rejected pose is announced again this often
  // Line faults (docs/RELIABILITY.md). Each bit written to a pty (samples and dialogue replies)
  // is flipped with this probability, independently (a binary symmetric channel). Each device's
  // line has its own channel, seeded from `fault_seed` and the device's place among the --live
  // devices: which of its bytes are hit does not depend on the timing of the others'.
  double bit_error_rate = 0;
  std::uint64_t fault_seed = 1;
  // Unplugs: the device's pty goes away (its master is closed and the link removed, as a USB
  // adapter's node does) and a new one appears at the same path `unplug_s` session seconds
  // later, the device powered up afresh. `mid`: halfway through the pose's planned dwell (the
  // pose announced, its answer outstanding); otherwise when the table leaves the pose.
  struct Unplug {
    int pose = 0;
    bool mid = true;
    int device = 0;  // index among the --live devices
  };
  std::vector<Unplug> unplugs;
  double unplug_s = 2.0;
  // A folder for the MIP devices' non-volatile storage (DIR/SIM0001.nvm.json, ...): what the
  // daemon saves into a device survives an unplug and the next run (sim/mip_storage.h). Empty:
  // saves last until the device's next power-up.
  std::string device_state_dir;
  // After the last pose the table stays there this many session seconds, the devices streaming
  // its stationary samples again (and answering dialogues): time for a write into the device
  // and its verification. An event {"event":"holding_end"} says when it begins.
  double hold_end_s = 0;
  // A reply lost on the line: the first time a device receives the 3DM command (set 0x0C) with
  // `descriptor` and `function` (1 write, 2 read, 3 save, ...), it carries it out but its reply
  // never reaches the host ({"event":"reply_lost"} on standard output). MIP devices only.
  struct LoseReply {
    std::uint8_t descriptor = 0;
    std::uint8_t function = 0;
  };
  std::vector<LoseReply> lose_replies;
  // The devices' serial numbers, one per --live device in order (MIP: the device info's serial;
  // Xbus: the device id, 8 hex digits). Missing: SIM0001, SIM0002, ... and 037000NN.
  std::vector<std::string> serials;
};

struct LiveSimReport {
  int poses = 0;
  int captured = 0;    // poses every device captured
  int unanswered = 0;  // poses given up (rejected after the retries, or no answer)
  int reconnects = 0;
  double held_s = 0;  // session seconds the table waited past the planned dwells
  std::vector<std::uint64_t> frames_sent, frames_withheld, frames_dropped;
  // Per device: bytes the pty took (what the daemon can read), bits flipped in them, bytes lost
  // in the sim's queue when a pty went away, frames not sent while unplugged, unplugs done.
  std::vector<std::uint64_t> bytes_written, bits_flipped, bytes_lost_unplugged, frames_unplugged,
      unplugs;
};

// Runs the session to its end. Pose answers and progress go to stdout as JSON lines. False with
// a message when a pty cannot be created or the daemon's socket never answered.
bool RunLiveSim(std::vector<LiveSimDevice>* devices, const LiveSimOptions& options,
                LiveSimReport* report, std::string* error);

}  // namespace turncal::sim
