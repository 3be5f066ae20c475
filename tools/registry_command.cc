#include "tools/registry_command.h"

#include <fmt/format.h>

#include <filesystem>
#include <fstream>
#include <iterator>
#include <memory>
#include <nlohmann/json.hpp>

#include "daemon/registry/registry_db.h"
#include "daemon/service/config.h"
#include "daemon/state/atomic_file.h"
#include "report/certificate.h"
#include "tools/certificate_command.h"
#include "tools/help_text.h"
#include "tools/registry_common.h"

namespace turncal::tools {

namespace {

using daemon::RegistryDb;
using daemon::RegistryRows;

// The codes Open and the Run functions below return.
constexpr Manual kRegistryManual = {
    "The calibration registry that every station's outbox fills (PostgreSQL; [registry] in "
    "turncald.toml). history SERIAL lists every calibration of a device at every station "
    "(a device that moved between stations shows both); latest SERIAL shows its latest "
    "passing calibration of each model with the parameters and their sigma; export writes "
    "CSV (one row per calibration and parameter) or JSON (whole documents with the writes "
    "into the device); stations shows each station's last contact; yield lists each batch's units "
    "and the share "
    "that passed every gate (--by station: per station); batch ID lists a batch's units slot "
    "by slot (docs/BATCH.md); drift SERIAL gives each parameter's turn-on-to-turn-on "
    "repeatability, trend per month with its sigma and the recalibration date from the unit's "
    "history (docs/REGISTRY.md \"Drift\"); certificate SERIAL "
    "--model M writes the calibration certificate of its latest passing (or --version N) "
    "calibration (docs/CERTIFICATES.md) and records it with its hash; verify FILE checks that "
    "a "
    "certificate is unchanged and that the registry issued it; migrate brings the schema to "
    "this turncal's "
    "version. The connection: --db, else TURNCAL_REGISTRY, else "
    "--config's [registry] (the password from its password_file).",
    "turncal registry history 6251.12345 --db 'host=db.lab dbname=turncal'\n"
    "turncal registry latest 6251.12345 --model accel13 --json\n"
    "turncal registry export --format csv --passing -o calibrations.csv\n"
    "turncal registry stations --config /etc/turncal/turncald.toml\n"
    "turncal registry yield --by station\n"
    "turncal registry batch cube4-20261129T045012Z --json\n"
    "turncal registry drift 6251.12345 --model accel13 --tolerance ax=0.002\n"
    "turncal registry certificate 6251.12345 --model mag13 -o cert.html --pdf cert.pdf\n"
    "turncal registry verify cert.html",
    "0 done (verify: unchanged and issued by the registry); 1 nothing found (history, "
    "latest, drift, certificate), or verify: edited or not issued by the registry; 2 the registry "
    "cannot be reached, refused the query, or a command-line mistake",
    "docs/REGISTRY.md, README (A registry for several stations)"};

constexpr const char* kHistorySql = R"sql(
SELECT c.calibrated_at, s.name AS station, c.device_name AS device, c.model, c.version,
       CASE WHEN c.passed THEN 'pass' ELSE 'FAIL' END AS gate,
       (SELECT count(*) FROM calibration_poses p WHERE p.calibration_id = c.id) AS poses,
       round(c.chi2::numeric, 2) AS chi2, c.dof, c.software, c.idempotency_key AS key
FROM calibrations c JOIN devices d ON d.id = c.device_id JOIN stations s ON s.id = c.station_id
WHERE d.serial = $1 AND ($2::text IS NULL OR c.model = $2)
ORDER BY c.calibrated_at, c.id)sql";

constexpr const char* kLatestSql = R"sql(
SELECT DISTINCT ON (c.model) c.model, c.version, c.calibrated_at, s.name AS station,
       c.device_name AS device,
       COALESCE(c.provenance->'device_identity'->>'model_name', d.model_name) AS model_name,
       COALESCE(c.provenance->'device_identity'->>'firmware', d.firmware) AS firmware,
       c.software, c.passed, c.parameters,
       c.idempotency_key AS key, c.document
FROM calibrations c JOIN devices d ON d.id = c.device_id JOIN stations s ON s.id = c.station_id
WHERE d.serial = $1 AND c.passed AND ($2::text IS NULL OR c.model = $2)
ORDER BY c.model, c.calibrated_at DESC, c.id DESC)sql";

constexpr const char* kStationsSql = R"sql(
SELECT s.name AS station, s.host, s.software, s.first_contact, s.last_contact,
       round(extract(epoch FROM now() - s.last_contact))::bigint AS seconds_ago,
       (SELECT count(*) FROM calibrations c WHERE c.station_id = s.id) AS calibrations,
       (SELECT max(c.calibrated_at) FROM calibrations c WHERE c.station_id = s.id)
         AS last_calibration
FROM stations s ORDER BY s.name)sql";

// One row per calibration and parameter (long format: every model fits one table).
constexpr const char* kExportCsvSql = R"sql(
SELECT s.name AS station, d.serial,
       COALESCE(c.provenance->'device_identity'->>'model_name', d.model_name) AS device_model,
       COALESCE(c.provenance->'device_identity'->>'firmware', d.firmware) AS firmware,
       c.device_name AS device, c.model, c.version, c.calibrated_at, c.passed, c.software,
       c.chi2, c.dof, c.p_value, p.key AS parameter, p.value->>'value' AS value,
       p.value->>'sigma' AS sigma, p.value->>'unit' AS unit, c.idempotency_key AS key
FROM calibrations c JOIN devices d ON d.id = c.device_id JOIN stations s ON s.id = c.station_id
CROSS JOIN LATERAL jsonb_each(c.parameters) AS p
WHERE ($1::text IS NULL OR d.serial = $1) AND ($2::text IS NULL OR s.name = $2)
  AND ($3::text IS NULL OR c.model = $3) AND (NOT $4::boolean OR c.passed)
ORDER BY c.calibrated_at, c.id, p.key)sql";

constexpr const char* kExportJsonSql = R"sql(
SELECT s.name AS station, d.serial,
       COALESCE(c.provenance->'device_identity'->>'model_name', d.model_name) AS device_model,
       COALESCE(c.provenance->'device_identity'->>'firmware', d.firmware) AS firmware, c.model,
       c.version, c.calibrated_at, c.received_at, c.passed, c.idempotency_key AS key,
       (SELECT coalesce(jsonb_agg(w.document ORDER BY w.written_at), '[]'::jsonb)
        FROM device_writes w WHERE w.device_id = d.id AND w.model = c.model
          AND w.version = c.version AND w.station_id = s.id) AS device_writes,
       c.document AS calibration
FROM calibrations c JOIN devices d ON d.id = c.device_id JOIN stations s ON s.id = c.station_id
WHERE ($1::text IS NULL OR d.serial = $1) AND ($2::text IS NULL OR s.name = $2)
  AND ($3::text IS NULL OR c.model = $3) AND (NOT $4::boolean OR c.passed)
ORDER BY c.calibrated_at, c.id)sql";

// RFC 4180: quoted when a cell holds a comma, a quote or a line break.
std::string CsvCell(const std::string& s) {
  if (s.find_first_of(",\"\r\n") == std::string::npos) return s;
  std::string q = "\"";
  for (char c : s) q += c == '"' ? std::string("\"\"") : std::string(1, c);
  return q + "\"";
}

int RunHistory(const RegistryArgs& a) {
  RegistryDb db;
  if (int rc = OpenRegistry(a, &db)) return rc;
  RegistryRows rows;
  std::string error;
  if (!db.Query(kHistorySql, {a.serial, Maybe(a.model)}, &rows, &error)) {
    fmt::print(stderr, "turncal registry: {}\n", error);
    return 2;
  }
  if (a.json) {
    fmt::print("{}\n", RowsJson(rows).dump(1));
  } else if (rows.rows.empty()) {
    fmt::print("serial {}: no calibration in the registry\n", a.serial);
  } else {
    fmt::print("serial {}: {} calibration(s)\n", a.serial, rows.rows.size());
    PrintTable(rows);
  }
  return rows.rows.empty() ? 1 : 0;
}

int RunLatest(const RegistryArgs& a) {
  RegistryDb db;
  if (int rc = OpenRegistry(a, &db)) return rc;
  RegistryRows rows;
  std::string error;
  if (!db.Query(kLatestSql, {a.serial, Maybe(a.model)}, &rows, &error)) {
    fmt::print(stderr, "turncal registry: {}\n", error);
    return 2;
  }
  const nlohmann::json list = RowsJson(rows);
  if (a.json) {
    fmt::print("{}\n", list.dump(1));
    return list.empty() ? 1 : 0;
  }
  if (list.empty()) {
    fmt::print("serial {}: no passing calibration{} in the registry\n", a.serial,
               a.model.empty() ? "" : " of " + a.model);
    return 1;
  }
  for (const auto& c : list) {
    fmt::print(
        "serial {} {} v{}: passed, {} at station {} (device {}, {} firmware {}), turncal {}\n",
        a.serial, c.value("model", ""), c.value("version", 0), c.value("calibrated_at", ""),
        c.value("station", ""), c.value("device", ""),
        c["model_name"].is_string() ? c["model_name"].get<std::string>() : "?",
        c["firmware"].is_string()
            ? c["firmware"].get<std::string>()
            : (c["firmware"].is_null() ? std::string("?") : c["firmware"].dump()),
        c.value("software", ""));
    for (const auto& [name, p] : c["parameters"].items()) {
      const nlohmann::json sigma = p.value("sigma", nlohmann::json());
      const nlohmann::json value = p.value("value", nlohmann::json());
      fmt::print(
          "  {:<10} {:>14}  sigma {}\n", name,
          value.is_number() ? fmt::format("{:.7g}", value.get<double>()) : std::string("(none)"),
          sigma.is_number() ? fmt::format("{:.3g}", sigma.get<double>())
                            : std::string("(not determined)"));
    }
  }
  return 0;
}

int RunStations(const RegistryArgs& a) {
  RegistryDb db;
  if (int rc = OpenRegistry(a, &db)) return rc;
  RegistryRows rows;
  std::string error;
  if (!db.Query(kStationsSql, {}, &rows, &error)) {
    fmt::print(stderr, "turncal registry: {}\n", error);
    return 2;
  }
  if (a.json) {
    fmt::print("{}\n", RowsJson(rows).dump(1));
  } else {
    PrintTable(rows);
  }
  return 0;
}

int RunExport(const RegistryArgs& a) {
  RegistryDb db;
  if (int rc = OpenRegistry(a, &db)) return rc;
  RegistryRows rows;
  std::string error;
  const bool csv = a.format == "csv";
  if (!db.Query(
          csv ? kExportCsvSql : kExportJsonSql,
          {Maybe(a.serial), Maybe(a.station), Maybe(a.model), a.passing_only ? "true" : "false"},
          &rows, &error)) {
    fmt::print(stderr, "turncal registry: {}\n", error);
    return 2;
  }
  if (!csv) return Emit(a, RowsJson(rows).dump(1) + "\n");
  std::string text;
  for (std::size_t c = 0; c < rows.columns.size(); ++c) {
    text += (c ? "," : "") + CsvCell(rows.columns[c]);
  }
  text += "\r\n";
  for (const auto& row : rows.rows) {
    for (std::size_t c = 0; c < row.size(); ++c) text += (c ? "," : "") + CsvCell(Cell(row[c]));
    text += "\r\n";
  }
  return Emit(a, text);
}

// The calibration of a serial and model a certificate is made of: --version N, else the latest
// passing one. With --station, only that station's.
constexpr const char* kCertificateSql = R"sql(
SELECT c.document, s.name AS station, d.serial, d.model_name, d.firmware, d.protocol,
       c.idempotency_key AS key, c.id
FROM calibrations c JOIN devices d ON d.id = c.device_id JOIN stations s ON s.id = c.station_id
WHERE d.serial = $1 AND c.model = $2 AND ($3::integer IS NULL OR c.version = $3::integer)
  AND ($4::text IS NULL OR s.name = $4) AND ($3::integer IS NOT NULL OR c.passed)
ORDER BY c.calibrated_at DESC, c.id DESC LIMIT 2)sql";

// Certificates are kept from schema 2 on.
bool HasCertificates(const RegistryDb& db) {
  if (db.schema_version() >= 2) return true;
  fmt::print(stderr,
             "turncal registry: the registry's schema is version {}; certificates need 2: run "
             "`turncal registry migrate` (or start a station of this turncal)\n",
             db.schema_version());
  return false;
}

int RunCertificate(const RegistryArgs& a) {
  RegistryDb db;
  if (int rc = OpenRegistry(a, &db)) return rc;
  if (!HasCertificates(db)) return 2;
  RegistryRows rows;
  std::string error;
  const std::optional<std::string> version =
      a.version > 0 ? std::optional<std::string>(std::to_string(a.version)) : std::nullopt;
  if (!db.Query(kCertificateSql, {a.serial, a.model, version, Maybe(a.station)}, &rows, &error)) {
    fmt::print(stderr, "turncal registry: {}\n", error);
    return 2;
  }
  if (rows.rows.empty()) {
    fmt::print(stderr,
               "turncal registry: serial {} has no {} calibration of {}{} in the registry\n",
               a.serial, version ? "version " + *version : std::string("passing"), a.model,
               a.station.empty() ? "" : " at station " + a.station);
    return 1;
  }
  // A version alone may name calibrations of two stations (each counts its own).
  if (version && rows.rows.size() > 1 && a.station.empty()) {
    fmt::print(stderr,
               "turncal registry: serial {} {} v{} was calibrated at more than one station; "
               "give --station\n",
               a.serial, a.model, *version);
    return 2;
  }
  const auto& row = rows.rows.front();
  report::CertificateSource source;
  source.calibration = nlohmann::json::parse(row[0].value_or("null"), nullptr, false);
  source.station = row[1].value_or("");
  source.source = "registry (key " + row[6].value_or("") + ")";
  // The identity the calibration was made with (its provenance); the registry adds the serial
  // (and, for a device that reported none, what the registry knows of it).
  source.identity = {{"serial", row[2].value_or("")}};
  const nlohmann::json provenance = source.calibration.is_object()
                                        ? source.calibration.value("provenance", nlohmann::json())
                                        : nlohmann::json();
  if (!provenance.is_object() || !provenance["device_identity"].is_object()) {
    if (row[3]) source.identity["model_name"] = *row[3];
    if (row[4]) source.identity["firmware"] = *row[4];
    if (row[5]) source.identity["protocol"] = *row[5];
  }
  source.issued_utc = a.issued;
  // A unit with history: its drift over its calibrations on the certificate (issue 39 item 3;
  // shown when a parameter has a trend, two sessions or more).
  nlohmann::json drift;
  std::string drift_error;
  if (AnalyseSerialDrift(&db, a.serial, a.model, {}, &drift, nullptr, &drift_error)) {
    source.drift = drift;
  } else {
    fmt::print(stderr,
               "turncal registry: the unit's drift could not be read ({}); the "
               "certificate shows none\n",
               drift_error);
  }
  if (int rc = WriteCertificate(source, a.output, a.pdf)) return rc;
  // The registry keeps the certificate and its hash: `turncal registry verify` then tells a
  // certificate it issued from one edited and given a recomputed hash.
  std::ifstream in(a.output, std::ios::binary);
  const std::string html((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  const report::CertificateCheck check = report::VerifyCertificateHtml(html);
  // The number the page shows (WriteCertificate rendered this content, so it parses).
  nlohmann::json content;
  std::string number;
  if (report::CertificateContent(source, &content, &error)) number = content.value("number", "");
  if (!check.ok || !db.Query("INSERT INTO certificates (sha256, calibration_id, number, html) "
                             "VALUES ($1, $2::bigint, $3, $4) ON CONFLICT (sha256) DO NOTHING",
                             {check.hash_claimed, row[7], number, html}, nullptr, &error)) {
    fmt::print(stderr, "turncal registry: the certificate was written but not registered: {}\n",
               check.ok ? error : check.reason);
    return 2;
  }
  fmt::print("registered: sha256 {} (turncal registry verify {})\n", check.hash_claimed, a.output);
  return 0;
}

// `registry verify FILE`: the file is unchanged (its hash) and the registry issued it.
int RunVerify(const RegistryArgs& a) {
  std::ifstream in(a.output, std::ios::binary);
  if (!in) {
    fmt::print(stderr, "turncal registry: cannot read '{}'\n", a.output);
    return 2;
  }
  const std::string html((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  const report::CertificateCheck check = report::VerifyCertificateHtml(html);
  if (check.not_a_certificate) {
    fmt::print(stderr, "turncal registry: '{}' is not a turncal certificate\n", a.output);
    return 2;
  }
  if (!check.ok) {
    fmt::print("FAILED: {}: {}\n", a.output, check.reason);
    return 1;
  }
  RegistryDb db;
  if (int rc = OpenRegistry(a, &db)) return rc;
  if (!HasCertificates(db)) return 2;
  RegistryRows rows;
  std::string error;
  if (!db.Query("SELECT t.number, t.issued_at, t.issued_by, c.idempotency_key, t.html = $2 "
                "FROM certificates t JOIN calibrations c ON c.id = t.calibration_id "
                "WHERE t.sha256 = $1",
                {check.hash_claimed, html}, &rows, &error)) {
    fmt::print(stderr, "turncal registry: {}\n", error);
    return 2;
  }
  if (rows.rows.empty() || rows.rows[0][4] != std::optional<std::string>("t")) {
    fmt::print(
        "FAILED: {}: its hash {} is consistent, but the registry did not issue it (edited and "
        "given a new hash, or made from a state directory and never registered)\n",
        a.output, check.hash_claimed);
    return 1;
  }
  const auto& r = rows.rows[0];
  fmt::print("verified: {}: certificate {} issued {} by {} for {}; sha256 {}\n", a.output,
             Cell(r[0]), Cell(r[1]), Cell(r[2]), Cell(r[3]), check.hash_claimed);
  return 0;
}

int RunMigrate(const RegistryArgs& a) {
  RegistryDb db;
  if (int rc = OpenRegistry(a, &db, /*migrate=*/true)) return rc;
  fmt::print("registry schema: version {} (this turncal knows {})\n", db.schema_version(),
             daemon::kRegistrySchemaVersion);
  return 0;
}

}  // namespace

void AddRegistryCommand(CLI::App* app) {
  CLI::App* cmd =
      app->add_subcommand("registry",
                          "the calibration registry across stations (PostgreSQL): history, latest, "
                          "export, stations, yield, batch, drift, certificate, verify, migrate");
  SetManual(cmd, kRegistryManual);
  cmd->require_subcommand(1);
  auto run = [](int rc) { throw CLI::RuntimeError(rc); };

  auto history = std::make_shared<RegistryArgs>();
  CLI::App* h = cmd->add_subcommand("history", "every calibration of a serial, at every station");
  h->add_option("SERIAL", history->serial, "the device's serial")->required();
  h->add_option("--model", history->model, "only this model");
  h->add_flag("--json", history->json, "as JSON");
  AddConnectionOptions(h, history);
  h->callback([history, run] { run(RunHistory(*history)); });

  auto latest = std::make_shared<RegistryArgs>();
  CLI::App* l = cmd->add_subcommand("latest", "the latest passing calibration of a serial");
  l->add_option("SERIAL", latest->serial, "the device's serial")->required();
  l->add_option("--model", latest->model, "only this model (default: the latest of each)");
  l->add_flag("--json", latest->json, "as JSON, with the whole calibration document");
  AddConnectionOptions(l, latest);
  l->callback([latest, run] { run(RunLatest(*latest)); });

  auto exporting = std::make_shared<RegistryArgs>();
  exporting->format = "csv";
  CLI::App* e = cmd->add_subcommand("export",
                                    "calibrations to CSV (one row per parameter) or "
                                    "JSON (whole documents)");
  e->add_option("--format", exporting->format, "csv or json")
      ->check(CLI::IsMember({"csv", "json"}))
      ->capture_default_str();
  e->add_option("--serial", exporting->serial, "only this serial");
  e->add_option("--station", exporting->station, "only this station");
  e->add_option("--model", exporting->model, "only this model");
  e->add_flag("--passing", exporting->passing_only, "only calibrations that passed the gate");
  e->add_option("-o,--output", exporting->output, "write here (atomically) instead of stdout");
  AddConnectionOptions(e, exporting);
  e->callback([exporting, run] { run(RunExport(*exporting)); });

  auto stations = std::make_shared<RegistryArgs>();
  CLI::App* s = cmd->add_subcommand("stations", "every station and its last contact");
  s->add_flag("--json", stations->json, "as JSON");
  AddConnectionOptions(s, stations);
  s->callback([stations, run] { run(RunStations(*stations)); });

  auto cert = std::make_shared<RegistryArgs>();
  CLI::App* c = cmd->add_subcommand(
      "certificate", "the calibration certificate of a serial's calibration, from the registry");
  c->add_option("SERIAL", cert->serial, "the device's serial")->required();
  c->add_option("--model", cert->model, "the model")->required();
  c->add_option("--version", cert->version, "this version (default: the latest passing one)");
  c->add_option("--station", cert->station, "only this station's calibrations");
  c->add_option("--issued", cert->issued, "the issue date shown on the certificate");
  c->add_option("-o,--output", cert->output, "the certificate (HTML)")->required();
  c->add_option("--pdf", cert->pdf, "also print it to this PDF with headless Chromium");
  AddConnectionOptions(c, cert);
  c->callback([cert, run] { run(RunCertificate(*cert)); });

  auto verify = std::make_shared<RegistryArgs>();
  CLI::App* v = cmd->add_subcommand(
      "verify", "a certificate is unchanged and the registry issued it (its hash is registered)");
  v->add_option("FILE", verify->output, "the certificate (HTML)")->required();
  AddConnectionOptions(v, verify);
  v->callback([verify, run] { run(RunVerify(*verify)); });

  auto migrate = std::make_shared<RegistryArgs>();
  CLI::App* m = cmd->add_subcommand(
      "migrate", "bring the registry's schema to this turncal's version (stations do it too)");
  AddConnectionOptions(m, migrate);
  m->callback([migrate, run] { run(RunMigrate(*migrate)); });

  AddRegistryBatchCommands(cmd);
  AddRegistryDriftCommand(cmd);
}

}  // namespace turncal::tools
