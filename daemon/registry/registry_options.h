#pragma once
// [registry] (issue 24, README "A registry for several stations"): where the station sends its
// calibrations. The connection is a libpq connection string (host, port, dbname, user, sslmode,
// sslrootcert, ...: TLS exactly as libpq does it); the password never stands in the
// configuration but in a file only turncald can read (systemd's LoadCredential).

#include <string>

namespace turncal::daemon {

struct RegistryOptions {
  // libpq connection string ("host=db.lab dbname=turncal user=station sslmode=verify-full"), or a
  // postgresql:// URI. Empty: no registry.
  std::string conninfo;
  // The password's file. Relative: in $CREDENTIALS_DIRECTORY (systemd's LoadCredential=), else
  // the working directory. Refused when its group or others may read it. Empty: none (libpq's
  // own ~/.pgpass, PGPASSFILE, peer or certificate authentication still apply).
  std::string password_file;
  // This station's name in the registry. Empty: the host name.
  std::string station;
  // Longest wait between two attempts while the database cannot be reached, seconds.
  double retry_max_s = 30.0;
  // Seconds a connection attempt may take (libpq's connect_timeout, unless the string sets it).
  int connect_timeout_s = 5;

  bool enabled() const { return !conninfo.empty(); }
};

// The password file's path as turncald opens it (see password_file).
std::string ResolvePasswordFile(const std::string& password_file);
// Reads the password (its first line). False with a message when the file cannot be read or
// group/others may read it.
bool ReadPasswordFile(const std::string& password_file, std::string* password, std::string* error);
// This machine's host name ("" when it cannot be read).
std::string HostName();
// The station's name: `configured`, else the host name (else "station").
std::string StationName(const std::string& configured);

}  // namespace turncal::daemon
