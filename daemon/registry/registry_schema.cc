// The registry's schema, as migrations (daemon/registry/registry_db.h). A migration is never edited
// once released: a change is a new migration appended here, applied in order by every station and
// by `turncal registry migrate`.

#include "daemon/registry/registry_db.h"

namespace turncal::daemon {

const std::vector<RegistryMigration>& RegistryMigrations() {
  static const std::vector<RegistryMigration> migrations = {
      {"stations, devices, calibrations with their poses, device writes", R"sql(
CREATE TABLE stations (
  id            bigserial PRIMARY KEY,
  name          text NOT NULL UNIQUE,
  host          text,
  software      text,
  first_contact timestamptz NOT NULL DEFAULT now(),
  last_contact  timestamptz NOT NULL DEFAULT now()
);
CREATE TABLE devices (
  id              bigserial PRIMARY KEY,
  serial          text NOT NULL UNIQUE,
  serial_reported boolean NOT NULL,
  model_name      text,
  firmware        text,
  protocol        text,
  first_seen      timestamptz NOT NULL DEFAULT now(),
  last_seen       timestamptz NOT NULL DEFAULT now()
);
CREATE TABLE calibrations (
  id              bigserial PRIMARY KEY,
  idempotency_key text NOT NULL UNIQUE,
  station_id      bigint NOT NULL REFERENCES stations(id),
  device_id       bigint NOT NULL REFERENCES devices(id),
  device_name     text NOT NULL,
  model           text NOT NULL,
  version         integer NOT NULL,
  passed          boolean NOT NULL,
  gate            jsonb,
  parameters      jsonb NOT NULL,
  parameter_order jsonb,
  covariance      jsonb,
  observability   jsonb,
  chi2            double precision,
  dof             integer,
  p_value         double precision,
  tolerances      jsonb,
  reference       jsonb,
  calibrator      jsonb,
  provenance      jsonb,
  software        text,
  calibrated_at   timestamptz NOT NULL,
  received_at     timestamptz NOT NULL DEFAULT now(),
  document        jsonb NOT NULL
);
CREATE INDEX calibrations_by_device ON calibrations (device_id, calibrated_at);
CREATE TABLE calibration_poses (
  calibration_id bigint NOT NULL REFERENCES calibrations(id) ON DELETE CASCADE,
  index          integer NOT NULL,
  pose           jsonb,
  record         jsonb,
  PRIMARY KEY (calibration_id, index)
);
CREATE TABLE device_writes (
  id              bigserial PRIMARY KEY,
  idempotency_key text NOT NULL UNIQUE,
  station_id      bigint NOT NULL REFERENCES stations(id),
  device_id       bigint NOT NULL REFERENCES devices(id),
  device_name     text NOT NULL,
  model           text,
  version         integer,
  operation       text,
  outcome         text,
  written_at      timestamptz,
  received_at     timestamptz NOT NULL DEFAULT now(),
  document        jsonb NOT NULL
);
CREATE INDEX device_writes_by_device ON device_writes (device_id, written_at);
)sql"},
      {"certificates issued from the registry, by their content hash", R"sql(
CREATE TABLE certificates (
  sha256         text PRIMARY KEY,
  calibration_id bigint NOT NULL REFERENCES calibrations(id),
  number         text NOT NULL,
  issued_at      timestamptz NOT NULL DEFAULT now(),
  issued_by      text NOT NULL DEFAULT current_user,
  html           text NOT NULL
);
CREATE INDEX certificates_by_calibration ON certificates (calibration_id);
)sql"},
      {"calibrations over temperature (issue 36): their polynomials", R"sql(
ALTER TABLE calibrations ADD COLUMN temperature jsonb;
)sql"},
      {"batches (issue 38): the units calibrated together, each calibration's batch and slot",
       R"sql(
CREATE TABLE batches (
  id         bigserial PRIMARY KEY,
  station_id bigint NOT NULL REFERENCES stations(id),
  name       text NOT NULL,
  fixture    text,
  units      integer,
  started_at timestamptz,
  UNIQUE (station_id, name)
);
ALTER TABLE calibrations ADD COLUMN batch_id bigint REFERENCES batches(id);
ALTER TABLE calibrations ADD COLUMN slot text;
CREATE INDEX calibrations_by_batch ON calibrations (batch_id);
)sql"},
  };
  return migrations;
}

}  // namespace turncal::daemon
