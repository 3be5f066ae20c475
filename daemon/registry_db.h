#pragma once
// The registry's database (issue 24): one PostgreSQL connection through libpq, the versioned
// schema and its migrations (daemon/registry_schema.cc), the insert of one outbox entry in one
// transaction, and the queries `turncal registry` asks. Blocking: the station calls it only from
// the outbox's own thread (daemon/registry_outbox.h), never from the event loop.
//
// The schema (version kRegistrySchemaVersion; docs/REGISTRY.md has every column):
//   schema_migrations  version, applied_at, description
//   stations           name, host, software, first_contact, last_contact
//   devices            serial, serial_reported, model_name, firmware, protocol, first/last_seen
//   calibrations       idempotency_key (unique), station, device, model, version, passed, gate,
//                      parameters, covariance, observability, chi2, dof, p_value, tolerances,
//                      reference, calibrator, provenance, software, calibrated_at, received_at,
//                      document (the calibration file as the station wrote it)
//   calibration_poses  calibration, index, pose (the table's angles), record (the statistics)
//   device_writes      idempotency_key (unique), station, device, model, version, operation,
//                      outcome, written_at, document (daemon/device_write.h's history entry)

#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "daemon/registry_options.h"

struct pg_conn;

namespace turncal::daemon {

inline constexpr int kRegistrySchemaVersion = 1;

// A query's answer: column names and rows of text (null: SQL NULL).
struct RegistryRows {
  std::vector<std::string> columns;
  // Each column's kind, from its PostgreSQL type: text, number, boolean or json.
  enum class Kind { kText, kNumber, kBoolean, kJson };
  std::vector<Kind> kinds;
  std::vector<std::vector<std::optional<std::string>>> rows;
};

class RegistryDb {
 public:
  RegistryDb() = default;
  ~RegistryDb();
  RegistryDb(const RegistryDb&) = delete;
  RegistryDb& operator=(const RegistryDb&) = delete;

  // Connects (the password from options.password_file) and brings the schema to
  // kRegistrySchemaVersion (migrations under an advisory lock: several stations may start at
  // once). A database whose schema is newer than this software knows is refused. False with a
  // message.
  bool Connect(const RegistryOptions& options, std::string* error);
  bool connected() const;
  void Close();
  // The schema version the database holds after Connect.
  int schema_version() const { return schema_version_; }

  // One outbox entry (daemon/registry_outbox.h) in one transaction: the station's last contact,
  // the device, then the calibration and its poses, or the device write. *inserted is false when
  // the registry already held the entry's key (a resend after a crash): nothing is written twice.
  bool Put(const nlohmann::json& entry, bool* inserted, std::string* error);
  // The station's last contact (a heartbeat while there is nothing to send).
  bool TouchStation(const std::string& station, const std::string& host, std::string* error);

  // A parameterised query ($1, $2, ...). False with the server's message.
  bool Query(const std::string& sql, const std::vector<std::optional<std::string>>& params,
             RegistryRows* out, std::string* error);

 private:
  bool Migrate(std::string* error);
  bool Exec(const std::string& sql, const std::vector<std::optional<std::string>>& params,
            RegistryRows* out, std::string* error);

  pg_conn* conn_ = nullptr;
  int schema_version_ = 0;
};

// The migrations, oldest first: migration i brings the schema from version i to i + 1.
struct RegistryMigration {
  const char* description;
  const char* sql;
};
const std::vector<RegistryMigration>& RegistryMigrations();

}  // namespace turncal::daemon
