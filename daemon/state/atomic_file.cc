#include "daemon/state/atomic_file.h"

#include <fcntl.h>
#include <fmt/format.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>

namespace turncal::daemon {

namespace {

// Writes all of `content` to `fd` (retrying short writes and EINTR); false with errno set.
bool WriteAll(int fd, std::string_view content) {
  std::size_t done = 0;
  while (done < content.size()) {
    const ssize_t n = ::write(fd, content.data() + done, content.size() - done);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) return false;
    done += static_cast<std::size_t>(n);
  }
  return true;
}

// Opens `path` as it is (following links, without creating it) and writes `content` into it.
bool WriteThrough(const std::string& path, std::string_view content, std::string* error) {
  auto fail = [&](const std::string& what) {
    if (error) *error = fmt::format("{}: {}", what, std::strerror(errno));
    return false;
  };
  const int fd = ::open(path.c_str(), O_WRONLY | O_TRUNC | O_CLOEXEC);
  if (fd < 0) return fail(fmt::format("cannot open '{}'", path));
  if (!WriteAll(fd, content)) {
    const bool ok = fail(fmt::format("cannot write '{}'", path));
    ::close(fd);
    return ok;
  }
  if (::close(fd) != 0) return fail(fmt::format("cannot close '{}'", path));
  return true;
}

}  // namespace

bool WriteFileAtomically(const std::string& path, std::string_view content, std::string* error) {
  auto fail = [&](const std::string& what) {
    if (error) *error = fmt::format("{}: {}", what, std::strerror(errno));
    return false;
  };
  // A path that exists and is not a regular file (/dev/null, /dev/stdout, a pipe, a symbolic
  // link) is written through, not replaced: renaming over it replaced /dev/null with a regular
  // file for every later process on the host (turncald --result-out /dev/null, 2026-11-27).
  struct stat st {};
  if (::lstat(path.c_str(), &st) == 0 && !S_ISREG(st.st_mode)) {
    if (S_ISDIR(st.st_mode)) {
      errno = EISDIR;
      return fail(fmt::format("cannot write '{}'", path));
    }
    return WriteThrough(path, content, error);
  }
  const std::string tmp = fmt::format("{}.tmp.{}", path, ::getpid());
  const int fd = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd < 0) return fail(fmt::format("cannot create '{}'", tmp));
  if (!WriteAll(fd, content)) {
    const bool ok = fail(fmt::format("cannot write '{}'", tmp));
    ::close(fd);
    ::unlink(tmp.c_str());
    return ok;
  }
  if (::fsync(fd) != 0) {
    const bool ok = fail(fmt::format("cannot sync '{}'", tmp));
    ::close(fd);
    ::unlink(tmp.c_str());
    return ok;
  }
  if (::close(fd) != 0) {
    const bool ok = fail(fmt::format("cannot close '{}'", tmp));
    ::unlink(tmp.c_str());
    return ok;
  }
  if (::rename(tmp.c_str(), path.c_str()) != 0) {
    const bool ok = fail(fmt::format("cannot rename '{}' to '{}'", tmp, path));
    ::unlink(tmp.c_str());
    return ok;
  }
  // The rename itself is durable once the directory is synced.
  const std::filesystem::path parent = std::filesystem::path(path).parent_path();
  const int dfd = ::open(parent.empty() ? "." : parent.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (dfd >= 0) {
    ::fsync(dfd);
    ::close(dfd);
  }
  return true;
}

bool ReadJsonFile(const std::filesystem::path& path, nlohmann::json* out, std::string* error) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream text;
  if (in) text << in.rdbuf();
  if (!in || in.bad()) {
    *error = fmt::format("cannot read '{}'", path.string());
    return false;
  }
  try {
    *out = nlohmann::json::parse(text.str());
  } catch (const nlohmann::json::exception& e) {  // parse errors, numbers out of range (1e400)
    *error = fmt::format("'{}' is not valid JSON: {}", path.string(), e.what());
    return false;
  }
  return true;
}

}  // namespace turncal::daemon
