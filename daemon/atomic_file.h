#pragma once
// Writes a whole file so that a reader sees either the old file or the new one, never a part:
// a temporary file beside it, written and fsynced, renamed over the target, and the directory
// fsynced (DESIGN.md: "a published calibration is never lost or half-written").

#include <string>
#include <string_view>

namespace turncal::daemon {

// False with a message naming the path and the system error.
bool WriteFileAtomically(const std::string& path, std::string_view content, std::string* error);

}  // namespace turncal::daemon
