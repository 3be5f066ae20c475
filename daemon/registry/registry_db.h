#pragma once
// The registry's database (issue 24): one PostgreSQL connection through libpq, the versioned
// schema and its migrations (daemon/registry/registry_schema.cc), the insert of one outbox entry in
// one transaction, and the queries `turncal registry` asks. Blocking: the station calls it only
// from the outbox's own thread (daemon/registry/registry_outbox.h), never from the event loop.
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
//                      outcome, written_at, document (daemon/state/device_write_record.h's history
//                      entry)
//   certificates       sha256 (the content hash), calibration, number, issued_at, issued_by,
//                      html (the certificate as issued: `turncal registry certificate`)
//   batches            station, name (the batch id), fixture, units (on the fixture),
//                      started_at; calibrations.batch_id and .slot point into it (issue 38)

#include <mutex>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "daemon/registry/registry_options.h"

struct pg_conn;
struct pg_cancel;

namespace turncal::daemon {

inline constexpr int kRegistrySchemaVersion = 4;

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
  // once). A newer schema than this software knows is used as it is: migrations only add
  // tables and columns with defaults, so an older station's inserts still fit. Every operation
  // is bounded: TCP keepalives, tcp_user_timeout, statement_timeout and lock_timeout, unless the
  // connection string sets them. False with a message.
  // `migrate` false (the queries of `turncal registry`): the schema is only read, never changed,
  // and a database without one is an error.
  bool Connect(const RegistryOptions& options, bool migrate, std::string* error);
  bool connected() const;
  void Close();
  // Any thread: asks the server to cancel the statement under way (the outbox stops).
  void Cancel();
  // The schema version the database holds after Connect.
  int schema_version() const { return schema_version_; }

  // One outbox entry (daemon/registry/registry_outbox.h) in one transaction: the station's last
  // contact, the device, then the calibration and its poses, or the device write. *inserted is
  // false when the registry already held the entry's key (a resend after a crash): nothing is
  // written twice.
  struct PutResult {
    bool already_there = false;  // the key was there: nothing written
    bool permanent = false;      // on failure: the entry itself is refused (SQLSTATE class 22,
                                 // 23, or a malformed entry); else it may pass later
  };
  bool Put(const nlohmann::json& entry, PutResult* result, std::string* error);
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
  std::mutex cancel_mutex_;
  pg_cancel* cancel_ = nullptr;  // PQgetCancel's, for Cancel from another thread
  int schema_version_ = 0;
  std::string last_sqlstate_;  // of the last failed Exec ("" when there was none)
};

// The migrations, oldest first: migration i brings the schema from version i to i + 1.
struct RegistryMigration {
  const char* description;
  const char* sql;
};
const std::vector<RegistryMigration>& RegistryMigrations();

}  // namespace turncal::daemon
