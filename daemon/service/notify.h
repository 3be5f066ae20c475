#pragma once
// systemd integration without libsystemd: the sd_notify(3) datagram protocol on $NOTIFY_SOCKET
// (READY=1, STATUS=..., WATCHDOG=1, RELOADING=1, STOPPING=1) and socket activation's
// $LISTEN_FDS / $LISTEN_PID (sd_listen_fds(3)). Both protocols are documented as stable; writing
// them directly avoids linking libsystemd (whose -dev package would upgrade the system's
// libsystemd0 on Debian 12) for two small functions. Outside systemd every call is a no-op.

#include <chrono>
#include <optional>
#include <string>

namespace turncal::daemon {

// Sends `state` (e.g. "READY=1\nSTATUS=listening") to $NOTIFY_SOCKET. False when there is no
// notify socket or the send failed (never fatal).
bool Notify(const std::string& state);

// The watchdog interval systemd expects pings at ($WATCHDOG_USEC, when $WATCHDOG_PID is ours or
// unset); nullopt when the watchdog is off.
std::optional<std::chrono::microseconds> WatchdogInterval();

// The first socket passed by socket activation (fd 3) when $LISTEN_FDS >= 1 and $LISTEN_PID is
// this process; nullopt otherwise. The variables are unset so children do not inherit them.
std::optional<int> ActivatedSocket();

}  // namespace turncal::daemon
