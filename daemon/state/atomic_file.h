#pragma once
// Whole files of the state directory. WriteFileAtomically writes a whole file so that a reader
// sees either the old file or the new one, never a part: a temporary file beside it, written and
// fsynced, renamed over the target, and the directory fsynced (DESIGN.md: "a published
// calibration is never lost or half-written"). A path that exists and is not a regular file
// (/dev/null, /dev/stdout, a pipe, a symbolic link) is written through instead, never replaced;
// a directory is refused. ReadJsonFile reads one JSON document.

#include <filesystem>
#include <nlohmann/json_fwd.hpp>
#include <string>
#include <string_view>

namespace turncal::daemon {

// False with a message naming the path and the system error.
bool WriteFileAtomically(const std::string& path, std::string_view content, std::string* error);

// The JSON document in `path`. False with a message naming the path ("cannot read", "is not
// valid JSON: " and the parser's reason, numbers out of range such as 1e400 included).
bool ReadJsonFile(const std::filesystem::path& path, nlohmann::json* out, std::string* error);

}  // namespace turncal::daemon
