#pragma once
// Logging in journald style (sd-daemon(3)): under systemd ($JOURNAL_STREAM is set) every line on
// stderr starts with its syslog priority, <3> error, <4> warning, <6> info, <7> debug, and has no
// timestamp (the journal adds its own); elsewhere the usual timestamped spdlog lines.

namespace turncal::daemon {

void ConfigureLogging();

}  // namespace turncal::daemon
