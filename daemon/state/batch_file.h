#pragma once
// The session's batch (issue 38): every calibration of one session -- the units of a fixture
// calibrated together, or a single unit -- carries the batch's id, so that the registry, the
// report and the certificates can say which units went through the table together.
//
// state_dir/batch.json holds it while the session lasts: {"id", "fixture", "started"} and, as the
// station last published it, each unit's state (Station::BatchStatus: "units", the counts). A
// restarted daemon reads it (the session resumes, and so does its batch); `reset` archives it
// with the journal, and the next session gets a new id. Without a state directory (a replay) the
// batch lives in memory only.

#include <nlohmann/json.hpp>
#include <string>

namespace turncal::daemon {

struct BatchInfo {
  std::string id;       // "LOT-17" as configured ([fixture] batch), else FIXTURE-20261129T045012Z
  std::string fixture;  // [fixture] name ("" without one)
  std::string started;  // UTC, ISO 8601: when the session's batch was opened
  nlohmann::json Json() const;
};

// A new batch: `configured_id` when not empty, else the fixture's name (or "batch") and the UTC
// time now.
BatchInfo NewBatch(const std::string& configured_id, const std::string& fixture);

// The batch of the session in `state_dir`: read from batch.json, else a new one written there
// atomically; an id an archived session (sessions/*/batch.json) already had gets "-2", "-3", ...
// A batch.json that does not parse is kept aside as batch.json.unreadable and a new
// batch is begun (*note says so). False with a message when nothing can be written; *batch still
// holds a batch to use (in memory only).
bool OpenBatch(const std::string& state_dir, const std::string& configured_id,
               const std::string& fixture, BatchInfo* batch, std::string* note, std::string* error);

// Rewrites batch.json with the batch's status (its id, fixture and start kept), atomically.
bool WriteBatchStatus(const std::string& state_dir, const nlohmann::json& status,
                      std::string* error);
// The batch.json of `state_dir` (null when there is none or it does not parse): the report's
// batch summary.
nlohmann::json ReadBatchStatus(const std::string& state_dir);

}  // namespace turncal::daemon
