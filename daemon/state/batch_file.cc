// The session's batch file (daemon/state/batch_file.h).

#include "daemon/state/batch_file.h"

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <vector>

#include "daemon/state/atomic_file.h"
#include "daemon/state/state_dir.h"
#include "drivers/transport/transport.h"

namespace fs = std::filesystem;

namespace turncal::daemon {

nlohmann::json BatchInfo::Json() const {
  return {{"id", id},
          {"fixture", fixture.empty() ? nlohmann::json() : nlohmann::json(fixture)},
          {"started", started}};
}

BatchInfo NewBatch(const std::string& configured_id, const std::string& fixture) {
  BatchInfo b;
  b.fixture = fixture;
  b.started = drivers::UtcNowIso8601();
  b.id = !configured_id.empty()
             ? configured_id
             : (fixture.empty() ? std::string("batch") : fixture) + "-" + UtcStamp();
  return b;
}

bool OpenBatch(const std::string& state_dir, const std::string& configured_id,
               const std::string& fixture, BatchInfo* batch, std::string* note,
               std::string* error) {
  note->clear();
  const fs::path path = StateDir(state_dir).Batch();
  std::error_code ec;
  if (fs::exists(path, ec)) {
    const nlohmann::json j = ReadBatchStatus(state_dir);
    const auto text = [&j](const char* key) {
      return j.is_object() && j.value(key, nlohmann::json()).is_string() ? j[key].get<std::string>()
                                                                         : std::string();
    };
    if (!text("id").empty()) {
      batch->id = text("id");
      batch->fixture = text("fixture");
      batch->started = text("started");
      if (!configured_id.empty() && configured_id != batch->id) {
        *note = "this session's batch is " + batch->id + " (batch.json); the configured '" +
                configured_id + "' applies from the next session (reset)";
      }
      return true;
    }
    fs::rename(path, fs::path(path.string() + ".unreadable"), ec);
    *note = "batch.json did not parse: kept as batch.json.unreadable, a new batch is begun";
  }
  *batch = NewBatch(configured_id, fixture);
  // An id an earlier session of this state directory had (a configured one kept over `reset`, or
  // two sessions in one second) gets -2, -3, ...: each session is its own batch.
  std::vector<std::string> used;
  for (const auto& entry : fs::directory_iterator(StateDir(state_dir).SessionsDir(), ec)) {
    const nlohmann::json j = ReadBatchStatus(entry.path().string());
    if (j.is_object() && j.value("id", nlohmann::json()).is_string()) {
      used.push_back(j["id"].get<std::string>());
    }
  }
  const std::string base = batch->id;
  for (int n = 2; std::find(used.begin(), used.end(), batch->id) != used.end(); ++n) {
    batch->id = base + "-" + std::to_string(n);
  }
  fs::create_directories(state_dir, ec);
  return WriteFileAtomically(path.string(), batch->Json().dump(1) + "\n", error);
}

bool WriteBatchStatus(const std::string& state_dir, const nlohmann::json& status,
                      std::string* error) {
  return WriteFileAtomically(StateDir(state_dir).Batch().string(), status.dump(1) + "\n", error);
}

nlohmann::json ReadBatchStatus(const std::string& state_dir) {
  std::ifstream in(StateDir(state_dir).Batch());
  if (!in) return nullptr;
  nlohmann::json j = nlohmann::json::parse(in, nullptr, false);
  return j.is_object() ? j : nlohmann::json();
}

}  // namespace turncal::daemon
