// `turncal registry yield` and `turncal registry batch ID` (issue 38; docs/REGISTRY.md): the
// batches the stations calibrated, their units and the share that passed, per batch or station.

#include <fmt/format.h>

#include "tools/registry_common.h"

namespace turncal::tools {

namespace {

using daemon::RegistryDb;
using daemon::RegistryRows;

// A unit of a batch passed when the latest version of every model it was calibrated with in the
// batch passed its gate (an override is not a pass). Units on the fixture that never got a
// calibration (held, never streamed) count as not passed: the batch's units are the most its
// calibrations said were on the fixture.
constexpr const char* kUnitsCte = R"sql(
WITH latest AS (
  SELECT DISTINCT ON (c.batch_id, c.device_id, c.model) c.batch_id, c.device_id, c.model,
    c.passed, c.slot, c.calibrated_at
  FROM calibrations c WHERE c.batch_id IS NOT NULL
  ORDER BY c.batch_id, c.device_id, c.model, c.version DESC, c.calibrated_at DESC, c.id DESC
), units AS (
  SELECT batch_id, device_id, bool_and(passed) AS passed, min(slot) AS slot,
    string_agg(model || CASE WHEN passed THEN '' ELSE ' (failed)' END, ', ' ORDER BY model)
      AS models,
    max(calibrated_at) AS last_calibrated
  FROM latest GROUP BY batch_id, device_id
))sql";

constexpr const char* kYieldByBatchSql = R"sql(
SELECT b.name AS batch, s.name AS station, b.fixture, b.started_at,
  GREATEST(b.units, count(*))::integer AS units,
  (count(*) FILTER (WHERE u.passed))::integer AS passed,
  round(100.0 * count(*) FILTER (WHERE u.passed) / GREATEST(b.units, count(*)), 1)
    AS yield_percent,
  max(u.last_calibrated) AS last_calibrated
FROM units u JOIN batches b ON b.id = u.batch_id JOIN stations s ON s.id = b.station_id
WHERE ($1::text IS NULL OR s.name = $1) AND ($2::text IS NULL OR b.name = $2)
GROUP BY b.id, b.name, s.name, b.fixture, b.started_at, b.units
ORDER BY b.started_at, b.id)sql";

constexpr const char* kYieldByStationSql = R"sql(
, per_batch AS (
  SELECT b.station_id, GREATEST(b.units, count(*)) AS units,
    count(*) FILTER (WHERE u.passed) AS passed
  FROM units u JOIN batches b ON b.id = u.batch_id GROUP BY b.id, b.station_id, b.units
)
SELECT s.name AS station, count(*)::integer AS batches, sum(p.units)::integer AS units,
  sum(p.passed)::integer AS passed,
  round(100.0 * sum(p.passed) / sum(p.units), 1) AS yield_percent
FROM per_batch p JOIN stations s ON s.id = p.station_id
WHERE ($1::text IS NULL OR s.name = $1)
GROUP BY s.name ORDER BY s.name)sql";

constexpr const char* kBatchSql = R"sql(
SELECT u.slot, d.serial, c.device_name AS device, u.passed, u.models, u.last_calibrated,
  s.name AS station
FROM units u JOIN batches b ON b.id = u.batch_id JOIN stations s ON s.id = b.station_id
  JOIN devices d ON d.id = u.device_id
  JOIN LATERAL (SELECT device_name FROM calibrations
                WHERE batch_id = u.batch_id AND device_id = u.device_id
                ORDER BY calibrated_at DESC LIMIT 1) c ON true
WHERE b.name = $1 AND ($2::text IS NULL OR s.name = $2)
ORDER BY s.name, u.slot NULLS LAST, d.serial)sql";

int Print(const RegistryArgs& a, const RegistryRows& rows) {
  if (a.json) {
    fmt::print("{}\n", RowsJson(rows).dump(1));
  } else {
    PrintTable(rows);
  }
  return 0;
}

int RunYield(const RegistryArgs& a, bool by_station) {
  RegistryDb db;
  if (int rc = OpenRegistry(a, &db)) return rc;
  RegistryRows rows;
  std::string error;
  const std::string sql =
      std::string(kUnitsCte) + (by_station ? kYieldByStationSql : kYieldByBatchSql);
  std::vector<std::optional<std::string>> params = {Maybe(a.station)};
  if (!by_station) params.push_back(Maybe(a.serial));  // --batch
  if (!db.Query(sql, params, &rows, &error)) {
    fmt::print(stderr, "turncal registry: {}\n", error);
    return 2;
  }
  if (rows.rows.empty()) {
    fmt::print(stderr, "turncal registry: no batch{}\n",
               a.station.empty() ? "" : " of station " + a.station);
    return 1;
  }
  return Print(a, rows);
}

int RunBatch(const RegistryArgs& a) {
  RegistryDb db;
  if (int rc = OpenRegistry(a, &db)) return rc;
  RegistryRows rows;
  std::string error;
  if (!db.Query(std::string(kUnitsCte) + kBatchSql, {a.serial, Maybe(a.station)}, &rows, &error)) {
    fmt::print(stderr, "turncal registry: {}\n", error);
    return 2;
  }
  if (rows.rows.empty()) {
    fmt::print(stderr, "turncal registry: no calibration of batch '{}'\n", a.serial);
    return 1;
  }
  return Print(a, rows);
}

}  // namespace

void AddRegistryBatchCommands(CLI::App* registry) {
  auto run = [](int rc) { throw CLI::RuntimeError(rc); };
  auto yield = std::make_shared<RegistryArgs>();
  auto by = std::make_shared<std::string>("batch");
  CLI::App* y = registry->add_subcommand(
      "yield", "units per batch (or station) and the share that passed every gate");
  y->add_option("--by", *by, "batch or station")
      ->check(CLI::IsMember({"batch", "station"}))
      ->capture_default_str();
  y->add_option("--station", yield->station, "only this station");
  y->add_option("--batch", yield->serial, "only this batch");
  y->add_flag("--json", yield->json, "as JSON");
  AddConnectionOptions(y, yield);
  y->callback([yield, by, run] { run(RunYield(*yield, *by == "station")); });

  auto batch = std::make_shared<RegistryArgs>();
  CLI::App* b = registry->add_subcommand(
      "batch", "a batch's units slot by slot: serial, models, passed (issue 38)");
  b->add_option("ID", batch->serial, "the batch id (status' batch.id, [fixture] batch)")
      ->required();
  b->add_option("--station", batch->station, "only this station's batch of that id");
  b->add_flag("--json", batch->json, "as JSON");
  AddConnectionOptions(b, batch);
  b->callback([batch, run] { run(RunBatch(*batch)); });
}

}  // namespace turncal::tools
