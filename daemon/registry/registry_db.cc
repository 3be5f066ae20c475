#include "daemon/registry/registry_db.h"

#include <fmt/format.h>
#include <libpq-fe.h>

#include <memory>

#include "turncal/version.h"

namespace turncal::daemon {

namespace {

struct ResultDeleter {
  void operator()(PGresult* r) const { PQclear(r); }
};
using Result = std::unique_ptr<PGresult, ResultDeleter>;

// libpq's message without its trailing newline.
std::string PgMessage(const char* text) {
  std::string s = text ? text : "";
  while (!s.empty() && (s.back() == '\n' || s.back() == ' ')) s.pop_back();
  return s;
}

// The entry's device in the registry: the serial the device reported (MIP's serial, Xbus's
// device id), else "STATION/DEVICE" (a replay, a protocol without one), marked not reported.
struct RegistryDevice {
  std::string serial;
  bool reported = false;
  std::optional<std::string> model_name, firmware, protocol;
};

std::optional<std::string> TextOf(const nlohmann::json& j, const char* key) {
  if (!j.is_object() || !j.contains(key) || j[key].is_null()) return std::nullopt;
  const nlohmann::json& v = j[key];
  return v.is_string() ? v.get<std::string>() : v.dump();
}

RegistryDevice DeviceOf(const nlohmann::json& entry) {
  RegistryDevice d;
  const nlohmann::json identity = entry.value("identity", nlohmann::json());
  std::optional<std::string> serial = TextOf(identity, "serial");
  if (!serial || serial->empty()) serial = TextOf(identity, "device_id");
  if (serial && !serial->empty()) {
    d.serial = *serial;
    d.reported = true;
  } else {
    d.serial = entry.value("station", "") + "/" + entry.value("device", "");
  }
  d.model_name = TextOf(identity, "model_name");
  if (!d.model_name) d.model_name = TextOf(identity, "product_code");
  d.firmware = TextOf(identity, "firmware");
  d.protocol = TextOf(identity, "protocol");
  return d;
}

constexpr const char* kUpsertStation = R"sql(
INSERT INTO stations (name, host, software) VALUES ($1, $2, $3)
ON CONFLICT (name) DO UPDATE SET host = EXCLUDED.host, software = EXCLUDED.software,
                                 last_contact = now()
RETURNING id)sql";

constexpr const char* kUpsertDevice = R"sql(
INSERT INTO devices (serial, serial_reported, model_name, firmware, protocol)
VALUES ($1, $2::boolean, $3, $4, $5)
ON CONFLICT (serial) DO UPDATE SET
  model_name = COALESCE(EXCLUDED.model_name, devices.model_name),
  firmware = COALESCE(EXCLUDED.firmware, devices.firmware),
  protocol = COALESCE(EXCLUDED.protocol, devices.protocol),
  last_seen = now()
RETURNING id)sql";

// Everything from the calibration's document as the station wrote it ($4), so the columns can
// never disagree with it.
constexpr const char* kInsertCalibration = R"sql(
INSERT INTO calibrations (idempotency_key, station_id, device_id, device_name, model, version,
  passed, gate, parameters, parameter_order, covariance, observability, chi2, dof, p_value,
  tolerances, reference, calibrator, provenance, software, calibrated_at, document, temperature,
  batch_id, slot)
SELECT $1, $2::bigint, $3::bigint, d->>'device', d->>'model', (d->>'version')::integer,
  COALESCE((d->'gate'->>'pass')::boolean, false), d->'gate',
  COALESCE(d->'params', d->'temperature'->'at'->'t0'), d->'parameter_order',
  d->'covariance',
  jsonb_strip_nulls(jsonb_build_object('rank', COALESCE(d->'rank', d->'temperature'->'rank'),
                                       'gauge', d->'gauge',
                                       'fit_check', d->'fit_check',
                                       'observability', d->'observability')),
  COALESCE(d->>'chi2', d->'temperature'->>'chi2')::double precision,
  round(COALESCE(d->>'dof', d->'temperature'->>'dof')::double precision)::integer,
  COALESCE(d->>'p_value', d->'temperature'->>'p_value')::double precision, d->'tolerances',
  d->'context', d->'calibrator',
  CASE WHEN jsonb_typeof(d->'provenance') = 'object' THEN (d->'provenance') - 'records' END,
  d->>'software', (d->>'time')::timestamptz, d, d->'temperature', $5::bigint,
  d->'batch'->>'slot'
FROM (SELECT $4::jsonb AS d) AS s
ON CONFLICT (idempotency_key) DO NOTHING
RETURNING id)sql";

// The calibration's batch (issue 38): one row per station and batch id; the units on the
// fixture as the largest any of its calibrations said.
constexpr const char* kUpsertBatch = R"sql(
INSERT INTO batches (station_id, name, fixture, units, started_at)
SELECT $1::bigint, b->>'id', b->>'fixture', (b->>'units')::integer,
  (b->>'started')::timestamptz
FROM (SELECT $2::jsonb AS b) AS s
ON CONFLICT (station_id, name) DO UPDATE
  SET units = GREATEST(batches.units, EXCLUDED.units),
      fixture = COALESCE(batches.fixture, EXCLUDED.fixture)
RETURNING id)sql";

// The poses and their records are aligned (daemon/station/device_pipeline.cc CalibrationJson).
constexpr const char* kInsertPoses = R"sql(
INSERT INTO calibration_poses (calibration_id, index, pose, record)
SELECT $1::bigint, (t.n - 1)::integer, t.pose, t.record
FROM ROWS FROM (jsonb_array_elements(CASE WHEN jsonb_typeof($2::jsonb -> 'poses') = 'array'
                                           THEN $2::jsonb -> 'poses' ELSE '[]'::jsonb END),
                jsonb_array_elements(CASE WHEN jsonb_typeof($2::jsonb -> 'records') = 'array'
                                           THEN $2::jsonb -> 'records' ELSE '[]'::jsonb END))
     WITH ORDINALITY AS t(pose, record, n))sql";

// A device write's entry is written again when its verification at the next pose completes it:
// the same row, updated.
constexpr const char* kUpsertDeviceWrite = R"sql(
INSERT INTO device_writes (idempotency_key, station_id, device_id, device_name, model, version,
  operation, outcome, written_at, document)
SELECT $1, $2::bigint, $3::bigint, d->>'device', d->>'model', (d->>'version')::integer,
  d->>'operation', d->>'state', (d->>'time')::timestamptz, d
FROM (SELECT $4::jsonb AS d) AS s
ON CONFLICT (idempotency_key) DO UPDATE SET outcome = EXCLUDED.outcome,
  document = EXCLUDED.document
  WHERE NOT (device_writes.document ? 'verification_at_pose')
    OR EXCLUDED.document ? 'verification_at_pose'
RETURNING id)sql";

}  // namespace

RegistryDb::~RegistryDb() { Close(); }

void RegistryDb::Close() {
  {
    std::lock_guard<std::mutex> lock(cancel_mutex_);
    if (cancel_) PQfreeCancel(cancel_);
    cancel_ = nullptr;
  }
  if (conn_) PQfinish(conn_);
  conn_ = nullptr;
  schema_version_ = 0;
}

void RegistryDb::Cancel() {
  std::lock_guard<std::mutex> lock(cancel_mutex_);
  char message[256];
  if (cancel_) PQcancel(cancel_, message, sizeof(message));
}

bool RegistryDb::connected() const { return conn_ && PQstatus(conn_) == CONNECTION_OK; }

bool RegistryDb::Connect(const RegistryOptions& options, bool migrate, std::string* error) {
  Close();
  std::string password;
  if (!options.password_file.empty() &&
      !ReadPasswordFile(options.password_file, &password, error)) {
    return false;
  }
  // Defaults first, then the connection string (expand_dbname: what it sets wins), then the
  // password from its file. Every wait is bounded: a connection attempt by connect_timeout, a
  // dead peer by keepalives and tcp_user_timeout, a statement and a lock wait (the migration's
  // advisory lock among them) by the server's timeouts.
  const std::string timeout = std::to_string(options.connect_timeout_s);
  std::vector<const char*> keys = {"connect_timeout",
                                   "application_name",
                                   "keepalives",
                                   "keepalives_idle",
                                   "keepalives_interval",
                                   "keepalives_count",
                                   "tcp_user_timeout",
                                   "options",
                                   "dbname"};
  std::vector<const char*> values = {
      timeout.c_str(),
      "turncald",
      "1",
      "10",
      "5",
      "3",
      "30000",
      "-c statement_timeout=60000 -c lock_timeout=30000 -c TimeZone=UTC -c DateStyle=ISO",
      options.conninfo.c_str()};
  if (!password.empty()) {
    keys.push_back("password");
    values.push_back(password.c_str());
  }
  keys.push_back(nullptr);
  values.push_back(nullptr);
  conn_ = PQconnectdbParams(keys.data(), values.data(), /*expand_dbname=*/1);
  if (!conn_ || PQstatus(conn_) != CONNECTION_OK) {
    *error = "cannot connect to the registry: " +
             PgMessage(conn_ ? PQerrorMessage(conn_) : "out of memory");
    Close();
    return false;
  }
  // The server's notices ("relation already exists, skipping") are not the user's business.
  PQsetNoticeProcessor(
      conn_, [](void*, const char*) {}, nullptr);
  {
    std::lock_guard<std::mutex> lock(cancel_mutex_);
    cancel_ = PQgetCancel(conn_);
  }
  if (migrate) {
    if (!Migrate(error)) {
      Close();
      return false;
    }
    return true;
  }
  RegistryRows rows;
  std::string why;
  if (!Exec("SELECT CASE WHEN to_regclass('schema_migrations') IS NULL THEN 0 ELSE "
            "(SELECT COALESCE(max(version), 0) FROM schema_migrations) END",
            {}, &rows, &why)) {
    *error = "registry schema: " + why;
    Close();
    return false;
  }
  schema_version_ = std::stoi(rows.rows.at(0).at(0).value_or("0"));
  if (schema_version_ == 0) {
    *error = "the registry has no schema yet: `turncal registry migrate`, or start a station";
    Close();
    return false;
  }
  return true;
}

bool RegistryDb::Exec(const std::string& sql, const std::vector<std::optional<std::string>>& params,
                      RegistryRows* out, std::string* error) {
  if (!conn_) {
    *error = "not connected to the registry";
    return false;
  }
  std::vector<const char*> values;
  values.reserve(params.size());
  for (const auto& p : params) values.push_back(p ? p->c_str() : nullptr);
  // Without parameters: the simple protocol, which takes several statements (a migration).
  Result r(params.empty() ? PQexec(conn_, sql.c_str())
                          : PQexecParams(conn_, sql.c_str(), static_cast<int>(values.size()),
                                         nullptr, values.data(), nullptr, nullptr, 0));
  const ExecStatusType status = r ? PQresultStatus(r.get()) : PGRES_FATAL_ERROR;
  last_sqlstate_.clear();
  if (status != PGRES_COMMAND_OK && status != PGRES_TUPLES_OK) {
    const char* state = r ? PQresultErrorField(r.get(), PG_DIAG_SQLSTATE) : nullptr;
    last_sqlstate_ = state ? state : "";
    *error = PgMessage(r ? PQresultErrorMessage(r.get()) : PQerrorMessage(conn_));
    if (error->empty()) *error = PgMessage(PQerrorMessage(conn_));
    return false;
  }
  if (out) {
    out->columns.clear();
    out->kinds.clear();
    out->rows.clear();
    const int n_columns = PQnfields(r.get());
    for (int c = 0; c < n_columns; ++c) {
      out->columns.emplace_back(PQfname(r.get(), c));
      // Built-in type OIDs (pg_type.h): bool; int8, int2, int4, float4, float8, numeric; json,
      // jsonb.
      switch (PQftype(r.get(), c)) {
        case 16:
          out->kinds.push_back(RegistryRows::Kind::kBoolean);
          break;
        case 20:
        case 21:
        case 23:
        case 700:
        case 701:
        case 1700:
          out->kinds.push_back(RegistryRows::Kind::kNumber);
          break;
        case 114:
        case 3802:
          out->kinds.push_back(RegistryRows::Kind::kJson);
          break;
        default:
          out->kinds.push_back(RegistryRows::Kind::kText);
      }
    }
    const int n_rows = PQntuples(r.get());
    for (int i = 0; i < n_rows; ++i) {
      std::vector<std::optional<std::string>> row;
      for (int c = 0; c < n_columns; ++c) {
        if (PQgetisnull(r.get(), i, c)) {
          row.emplace_back(std::nullopt);
        } else {
          row.emplace_back(std::string(PQgetvalue(r.get(), i, c),
                                       static_cast<std::size_t>(PQgetlength(r.get(), i, c))));
        }
      }
      out->rows.push_back(std::move(row));
    }
  }
  return true;
}

bool RegistryDb::Query(const std::string& sql,
                       const std::vector<std::optional<std::string>>& params, RegistryRows* out,
                       std::string* error) {
  return Exec(sql, params, out, error);
}

bool RegistryDb::Migrate(std::string* error) {
  const auto& migrations = RegistryMigrations();
  RegistryRows rows;
  std::string why;
  // One station migrates at a time (a transaction-level advisory lock, released at COMMIT).
  if (!Exec("BEGIN", {}, nullptr, &why) ||
      !Exec("SELECT pg_advisory_xact_lock(7247811235)", {}, nullptr, &why) ||
      !Exec("CREATE TABLE IF NOT EXISTS schema_migrations (version integer PRIMARY KEY, "
            "description text NOT NULL, applied_at timestamptz NOT NULL DEFAULT now())",
            {}, nullptr, &why) ||
      !Exec("SELECT COALESCE(max(version), 0) FROM schema_migrations", {}, &rows, &why)) {
    Exec("ROLLBACK", {}, nullptr, &why);
    *error = "registry schema: " + why;
    return false;
  }
  int version = std::stoi(rows.rows.at(0).at(0).value_or("0"));
  for (; version < static_cast<int>(migrations.size()); ++version) {
    const RegistryMigration& m = migrations[static_cast<std::size_t>(version)];
    if (!Exec(m.sql, {}, nullptr, &why) ||
        !Exec("INSERT INTO schema_migrations (version, description) VALUES ($1::integer, $2)",
              {std::to_string(version + 1), std::string(m.description)}, nullptr, &why)) {
      std::string ignored;
      Exec("ROLLBACK", {}, nullptr, &ignored);
      *error =
          fmt::format("registry schema: migration {} ({}): {}", version + 1, m.description, why);
      return false;
    }
  }
  if (!Exec("COMMIT", {}, nullptr, &why)) {
    *error = "registry schema: " + why;
    return false;
  }
  schema_version_ = std::max(version, static_cast<int>(migrations.size()));
  return true;
}

bool RegistryDb::TouchStation(const std::string& station, const std::string& host,
                              std::string* error) {
  return Exec(kUpsertStation, {station, host, std::string(kVersion)}, nullptr, error);
}

bool RegistryDb::Put(const nlohmann::json& entry, PutResult* result, std::string* error) {
  *result = PutResult();
  const std::string kind = entry.value("kind", "");
  if (kind != "calibration" && kind != "device_write") {
    *error = fmt::format("outbox entry of unknown kind '{}'", kind);
    result->permanent = true;
    return false;
  }
  RegistryDevice device;
  std::string document, provenance;
  try {
    device = DeviceOf(entry);
    document = entry.at("document").dump();
    const nlohmann::json& d = entry.at("document");
    provenance = d.is_object() && d.contains("provenance") ? d["provenance"].dump() : "null";
  } catch (const std::exception& e) {  // nlohmann's type errors: not an entry
    *error = std::string("malformed outbox entry: ") + e.what();
    result->permanent = true;
    return false;
  }
  // A calibration's batch (issue 38; none before it): {"id", "fixture", "units", "started"}.
  std::optional<std::string> batch;
  if (kind == "calibration") {
    const nlohmann::json& d = entry.at("document");
    if (d.is_object() && d.contains("batch") && d["batch"].is_object() &&
        d["batch"].value("id", nlohmann::json()).is_string()) {
      batch = d["batch"].dump();
    }
  }
  RegistryRows station_row, device_row, batch_row, row;
  std::string why;
  bool ok = Exec("BEGIN", {}, nullptr, &why) &&
            Exec(kUpsertStation,
                 {entry.value("station", ""), entry.value("host", ""), entry.value("software", "")},
                 &station_row, &why) &&
            Exec(kUpsertDevice,
                 {device.serial, device.reported ? "true" : "false", device.model_name,
                  device.firmware, device.protocol},
                 &device_row, &why) &&
            (!batch || Exec(kUpsertBatch, {station_row.rows.at(0).at(0), batch}, &batch_row, &why));
  if (ok && kind == "calibration") {
    ok = Exec(kInsertCalibration,
              {entry.value("key", ""), station_row.rows.at(0).at(0), device_row.rows.at(0).at(0),
               document, batch ? batch_row.rows.at(0).at(0) : std::nullopt},
              &row, &why);
  } else if (ok) {
    ok = Exec(kUpsertDeviceWrite,
              {entry.value("key", ""), station_row.rows.at(0).at(0), device_row.rows.at(0).at(0),
               document},
              &row, &why);
  }
  if (ok && kind == "calibration") {
    result->already_there = row.rows.empty();
    if (!row.rows.empty()) ok = Exec(kInsertPoses, {row.rows[0][0], provenance}, nullptr, &why);
  } else if (ok && kind == "device_write") {
    // Inserted, or updated by its completed entry: sent either way. Nothing returned: the
    // registry's row already held the verification this entry lacks.
    result->already_there = row.rows.empty();
  }
  if (ok) ok = Exec("COMMIT", {}, nullptr, &why);
  if (!ok) {
    // Class 22 (data exception) and 23 (integrity constraint): this entry will never fit.
    // Anything else (a read-only standby, a full disk, a cancel, a timeout, a lost connection,
    // a missing privilege) may pass later.
    result->permanent = last_sqlstate_.rfind("22", 0) == 0 || last_sqlstate_.rfind("23", 0) == 0;
    std::string ignored;
    if (conn_ && PQtransactionStatus(conn_) != PQTRANS_IDLE)
      Exec("ROLLBACK", {}, nullptr, &ignored);
    *error = why;
    return false;
  }
  return true;
}

}  // namespace turncal::daemon
