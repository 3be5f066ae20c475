#pragma once
// `turncal sim --live PTY... --controller SOCKET`: the simulator plays the turntable, its sensors
// and the lab's controller against a running turncald. Each simulated device streams its frames
// into a pseudo-terminal at real time (times the speed) and answers the daemon's configuration
// dialogue through the device emulator (tools/sim_device.h), sending no samples while the host
// has it idle or in config state. The controller announces every pose on the daemon's socket
// when the table has settled and -- like a real controller -- holds the table there until every
// device has answered: while it waits past the planned dwell, the devices keep streaming the
// pose's stationary samples again (device time and counters advancing; forwards, then backwards,
// so the bias wander has no step where the loop closes). Before the first move the table rests
// at home, streaming the start's samples the same way, until the daemon's status says every
// device has measured its noise (or `answer_timeout_s` passed), as a controller that waits for
// NOISE_MEASURED would. A rejected pose is
// announced again (up to `retries` times). A daemon that goes away (kill -9) is reconnected,
// and the pose it did not answer is announced again.
//
// PTY: a path that does not exist (or is a symlink) gets a new pseudo-terminal, linked there; an
// existing character device (a socat pty, a real serial port) is used as it is.

#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "tools/sim_capture.h"

namespace turncal::tools {

struct LiveSimDevice {
  std::string path;
  SimCapture capture;
};

struct LiveSimOptions {
  double speed = 1.0;
  std::string controller;         // turncald's socket; empty: pose events on stdout only
  double connect_timeout_s = 60;  // real seconds to wait for the daemon's socket
  double answer_timeout_s = 120;  // session seconds the table waits for an answer
  int retries = 2;                // a rejected pose is announced again this often
};

struct LiveSimReport {
  int poses = 0;
  int captured = 0;    // poses every device captured
  int unanswered = 0;  // poses given up (rejected after the retries, or no answer)
  int reconnects = 0;
  double held_s = 0;  // session seconds the table waited past the planned dwells
  std::vector<std::uint64_t> frames_sent, frames_withheld, frames_dropped;
};

// Runs the session to its end. Pose answers and progress go to stdout as JSON lines. False with
// a message when a pty cannot be created or the daemon's socket never answered.
bool RunLiveSim(std::vector<LiveSimDevice>* devices, const LiveSimOptions& options,
                LiveSimReport* report, std::string* error);

}  // namespace turncal::tools
