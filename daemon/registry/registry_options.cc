#include "daemon/registry/registry_options.h"

#include <fmt/format.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>

namespace turncal::daemon {

std::string ResolvePasswordFile(const std::string& password_file) {
  if (password_file.empty() || std::filesystem::path(password_file).is_absolute()) {
    return password_file;
  }
  if (const char* credentials = std::getenv("CREDENTIALS_DIRECTORY"); credentials && *credentials) {
    return (std::filesystem::path(credentials) / password_file).string();
  }
  return password_file;
}

bool ReadPasswordFile(const std::string& password_file, std::string* password, std::string* error) {
  const std::string path = ResolvePasswordFile(password_file);
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0) {
    *error = fmt::format("registry password file '{}': {}", path, std::strerror(errno));
    return false;
  }
  // As libpq treats ~/.pgpass: a password others may read is refused, not used. A systemd
  // credential is private to the service whatever its mode bits show (systemd grants the
  // service's user read access with an ACL, whose mask then shows as group bits): there only
  // the "other" bits count.
  const char* credentials = std::getenv("CREDENTIALS_DIRECTORY");
  const bool credential =
      credentials && *credentials &&
      std::filesystem::path(path).parent_path() == std::filesystem::path(credentials);
  if ((st.st_mode & (credential ? S_IRWXO : (S_IRWXG | S_IRWXO))) != 0) {
    *error = fmt::format(
        "registry password file '{}' may be read by group or others (mode {:04o}): chmod 600 it "
        "or give it with systemd's LoadCredential=",
        path, st.st_mode & 07777);
    return false;
  }
  std::ifstream in(path);
  if (!in) {
    *error = fmt::format("cannot read the registry password file '{}'", path);
    return false;
  }
  std::getline(in, *password);
  if (!password->empty() && password->back() == '\r') password->pop_back();  // CRLF
  if (password->empty()) {
    *error = fmt::format("the registry password file '{}' is empty", path);
    return false;
  }
  return true;
}

std::string HostName() {
  char name[256] = {};
  if (::gethostname(name, sizeof(name) - 1) != 0) return "";
  return name;
}

std::string StationName(const std::string& configured) {
  if (!configured.empty()) return configured;
  const std::string host = HostName();
  return host.empty() ? "station" : host;
}

}  // namespace turncal::daemon
