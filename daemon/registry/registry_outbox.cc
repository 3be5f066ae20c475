#include "daemon/registry/registry_outbox.h"

#include <fcntl.h>
#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <vector>

#include "daemon/registry/registry_db.h"
#include "daemon/state/atomic_file.h"
#include "daemon/state/state_dir.h"
#include "drivers/transport/transport.h"
#include "turncal/version.h"

namespace turncal::daemon {

namespace fs = std::filesystem;

namespace {

// Between two heartbeats (the station's last contact) while nothing waits.
constexpr auto kHeartbeat = std::chrono::seconds(60);
constexpr double kFirstRetryS = 0.5;

std::string SerialOrName(const nlohmann::json& identity, const std::string& device) {
  for (const char* key : {"serial", "device_id"}) {
    if (identity.is_object() && identity.contains(key) && identity[key].is_string() &&
        !identity[key].get<std::string>().empty()) {
      return identity[key].get<std::string>();
    }
  }
  return device;
}

nlohmann::json IdentityOf(const nlohmann::json& calibration) {
  const nlohmann::json provenance = calibration.value("provenance", nlohmann::json::object());
  return provenance.is_object() ? provenance.value("device_identity", nlohmann::json())
                                : nlohmann::json();
}

// A calibration's id in this state directory (sent.log): device, model, version and time.
std::string CalibrationLocalId(const nlohmann::json& calibration) {
  return fmt::format("{}.{}.v{}@{}", calibration.value("device", ""),
                     calibration.value("model", ""), calibration.value("version", 0),
                     calibration.value("time", ""));
}

// Letters, digits and -._ only: a file name from a device or model name.
std::string Sanitized(const std::string& text) {
  std::string s = text;
  for (char& c : s) {
    if (!std::isalnum(static_cast<unsigned char>(c)) && c != '-' && c != '.' && c != '_') c = '_';
  }
  return s.substr(0, 120);
}

// The entries waiting, oldest first.
std::vector<fs::path> WaitingEntries(const std::string& dir) {
  std::vector<fs::path> entries;
  std::error_code ec;
  for (const auto& e : fs::directory_iterator(dir, ec)) {
    const std::string name = e.path().filename().string();
    if (e.is_regular_file(ec) && name.size() > 5 && name.ends_with(".json")) {
      entries.push_back(e.path());
    }
  }
  std::sort(entries.begin(), entries.end());
  return entries;
}

// Test hook (tests/daemon/e2e_registry_test.py): hold after the first commit, before the entry
// leaves the outbox, so that a kill -9 lands exactly there.
bool HoldAfterCommit() {
  const char* v = std::getenv("TURNCAL_TEST_REGISTRY_HOLD_AFTER_COMMIT");
  return v && *v && std::string(v) != "0";
}

}  // namespace

RegistryOutbox::RegistryOutbox(std::string state_dir, RegistryOptions options)
    : state_dir_(std::move(state_dir)),
      options_(std::move(options)),
      station_(StationName(options_.station)),
      host_(HostName()) {}

RegistryOutbox::~RegistryOutbox() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stop_ = true;
  }
  wake_.notify_all();
  // A statement under way ends at once; a connection attempt within connect_timeout.
  if (db_) db_->Cancel();
  if (thread_.joinable()) thread_.join();
}

std::string RegistryOutbox::Dir() const { return StateDir(state_dir_).OutboxDir().string(); }

std::string RegistryOutbox::CalibrationKey(const std::string& station,
                                           const nlohmann::json& calibration) {
  return fmt::format("{}/{}/{}/v{}/{}", station,
                     SerialOrName(IdentityOf(calibration), calibration.value("device", "")),
                     calibration.value("model", ""), calibration.value("version", 0),
                     calibration.value("time", ""));
}

namespace {

// The sequence number at the start of an outbox file's name (0 when there is none).
std::uint64_t OutboxSequenceOf(const fs::path& path) {
  const std::string name = path.filename().string();
  std::uint64_t n = 0;
  for (char c : name) {
    if (c < '0' || c > '9') break;
    n = n * 10 + static_cast<std::uint64_t>(c - '0');
  }
  return n;
}

}  // namespace

bool RegistryOutbox::Start(std::string* error) {
  std::error_code ec;
  fs::create_directories(StateDir(state_dir_).OutboxRejectedDir(), ec);
  if (ec) {
    *error = fmt::format("registry: cannot create '{}': {}", Dir(), ec.message());
    return false;
  }
  // The entries an earlier run left: counted now, sent by the thread; the new ones sort after
  // them (a sequence, not the clock, which may step back).
  for (const auto& path : WaitingEntries(Dir())) {
    nlohmann::json entry;
    std::string why;
    if (ReadJsonFile(path, &entry, &why) && entry.is_object() && entry["local_id"].is_string()) {
      queued_ids_.insert(entry["local_id"].get<std::string>());
    }
    sequence_ = std::max(sequence_, OutboxSequenceOf(path));
    ++depth_;
  }
  for (const auto& path : WaitingEntries(StateDir(state_dir_).OutboxRejectedDir().string())) {
    nlohmann::json entry;
    std::string why;
    if (ReadJsonFile(path, &entry, &why) && entry.is_object() && entry["local_id"].is_string()) {
      rejected_ids_.insert(entry["local_id"].get<std::string>());
    }
  }
  db_ = std::make_unique<RegistryDb>();
  thread_ = std::thread([this] { Run(); });
  return true;
}

bool RegistryOutbox::WriteEntry(const std::string& kind, const std::string& local_id, bool unique,
                                nlohmann::json entry, std::string* error) {
  std::uint64_t sequence = 0;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    // Reserved before the file is written: a reconciliation and the worker never both write it.
    if (!queued_ids_.insert(local_id).second && unique) return true;
    sequence = ++sequence_;
  }
  const std::string name = fmt::format("{:012}-{}-{}.json", sequence, kind, Sanitized(local_id));
  entry["schema"] = 1;
  entry["kind"] = kind;
  entry["local_id"] = local_id;
  entry["station"] = station_;
  entry["host"] = host_;
  entry["software"] = kVersion;
  entry["queued"] = drivers::UtcNowIso8601();
  if (!WriteFileAtomically((fs::path(Dir()) / name).string(), entry.dump() + "\n", error)) {
    *error = "registry outbox: " + *error;
    {
      // The thread looks for what is not yet sent again after its next wait (the calibration's
      // own file holds it): a full disk loses no registry entry once space is back.
      std::lock_guard<std::mutex> lock(mutex_);
      queued_ids_.erase(local_id);
      reconcile_due_ = true;
    }
    return false;
  }
  {
    std::lock_guard<std::mutex> lock(mutex_);
    ++depth_;
    added_ = true;
  }
  wake_.notify_all();
  return true;
}

bool RegistryOutbox::AddCalibration(const nlohmann::json& calibration, std::string* error) {
  nlohmann::json entry = {{"key", CalibrationKey(station_, calibration)},
                          {"device", calibration.value("device", "")},
                          {"identity", IdentityOf(calibration)},
                          {"document", calibration}};
  return WriteEntry("calibration", CalibrationLocalId(calibration), /*unique=*/true,
                    std::move(entry), error);
}

bool RegistryOutbox::AddDeviceWrite(const nlohmann::json& write_entry,
                                    const nlohmann::json& identity, const std::string& history_path,
                                    std::string* error) {
  const std::string device = write_entry.value("device", "");
  const std::string file = fs::path(history_path).filename().string();
  nlohmann::json entry = {
      {"key", fmt::format("{}/{}/write/{}", station_, SerialOrName(identity, device), file)},
      {"device", device},
      {"identity", identity},
      {"document", write_entry}};
  return WriteEntry("device_write", "write:" + file, /*unique=*/false, std::move(entry), error);
}

nlohmann::json RegistryOutbox::Status() const {
  std::lock_guard<std::mutex> lock(mutex_);
  auto or_null = [](const std::string& s) {
    return s.empty() ? nlohmann::json() : nlohmann::json(s);
  };
  return {{"station", station_},
          {"connected", connected_},
          {"schema", schema_},
          {"depth", depth_},
          {"sent", sent_},
          {"already_there", already_there_},
          {"rejected", rejected_},
          {"last_error", or_null(last_error_)},
          {"last_error_time", or_null(last_error_time_)},
          {"last_sent_time", or_null(last_sent_time_)}};
}

void RegistryOutbox::NoteError(const std::string& error, bool connection) {
  std::lock_guard<std::mutex> lock(mutex_);
  if (error != last_error_) spdlog::warn("registry: {}", error);
  last_error_ = error;
  last_error_time_ = drivers::UtcNowIso8601();
  if (connection) connected_ = false;
}

void RegistryOutbox::Reconcile() {
  std::set<std::string> sent;
  {
    std::ifstream log(StateDir(state_dir_).SentLog());
    for (std::string line; std::getline(log, line);) sent.insert(line);
  }
  // Oldest first by the calibration's own time (v10 sorts before v2 by name), so that the
  // registry's device row ends with the newest identity.
  std::vector<std::pair<std::string, nlohmann::json>> missing;
  const StateDir places(state_dir_);
  for (const fs::path& folder : {places.HistoryDir(), places.CalibrationsDir()}) {
    std::error_code ec;
    for (const auto& e : fs::directory_iterator(folder, ec)) {
      if (e.path().extension() != ".json") continue;
      nlohmann::json calibration;
      std::string why;
      if (!ReadJsonFile(e.path(), &calibration, &why) || !calibration.is_object() ||
          calibration.value("class", "") != "CALIBRATION") {
        continue;
      }
      const std::string id = CalibrationLocalId(calibration);
      std::lock_guard<std::mutex> lock(mutex_);
      if (stop_) return;
      if (sent.count(id) || queued_ids_.count(id) || rejected_ids_.count(id)) continue;
      missing.emplace_back(calibration.value("time", "") + "#" + id, std::move(calibration));
    }
  }
  std::sort(missing.begin(), missing.end(),
            [](const auto& a, const auto& b) { return a.first < b.first; });
  int added = 0;
  for (const auto& [order, calibration] : missing) {
    std::string why;
    if (AddCalibration(calibration, &why)) {
      ++added;
    } else {
      NoteError(why, /*connection=*/false);
    }
  }
  if (added > 0) {
    spdlog::info("registry: {} calibration(s) of this state directory were not yet sent; queued",
                 added);
  }
}

void RegistryOutbox::Reject(const std::string& path, const std::string& local_id,
                            const std::string& why) {
  std::error_code ec;
  fs::rename(path, StateDir(state_dir_).OutboxRejectedDir() / fs::path(path).filename(), ec);
  spdlog::error("registry: {} moved to outbox/rejected/: {}", fs::path(path).filename().string(),
                why);
  NoteError(fmt::format("{} rejected: {}", fs::path(path).filename().string(), why),
            /*connection=*/false);
  std::lock_guard<std::mutex> lock(mutex_);
  ++rejected_;
  --depth_;
  queued_ids_.erase(local_id);
  rejected_ids_.insert(local_id);
}

bool RegistryOutbox::SendEntry(const std::string& path, bool hold_after_commit) {
  RegistryDb* db = db_.get();
  nlohmann::json entry;
  std::string error;
  if (!ReadJsonFile(path, &entry, &error)) {
    std::error_code ec;
    if (fs::exists(path, ec) && !fs::is_regular_file(path, ec)) {
      Reject(path, "", error);
      return true;
    }
    // A file that cannot be read now (EMFILE, EIO) is tried again later; one that is not JSON
    // (edited by hand, a disk fault) is kept aside.
    if (error.find("is not JSON") == std::string::npos) {
      NoteError(error, /*connection=*/false);
      return false;
    }
    Reject(path, "", error);
    return true;
  }
  if (!entry.is_object() || !entry.contains("document") || !entry["local_id"].is_string()) {
    Reject(path, "", "not an outbox entry");
    return true;
  }
  const std::string local_id = entry["local_id"].get<std::string>();
  RegistryDb::PutResult result;
  if (!db->Put(entry, &result, &error)) {
    if (result.permanent) {
      // The server refused this entry itself (SQLSTATE class 22 data or 23 constraint): kept
      // aside so that the others still go; the station's own files keep it.
      Reject(path, local_id, error);
      return true;
    }
    db->Close();  // anything else may pass: the connection is made afresh after a wait
    NoteError(error);
    return false;
  }
  if (hold_after_commit) {
    spdlog::warn("registry: {} committed; holding before it leaves the outbox (test hook)",
                 entry.value("key", ""));
    std::unique_lock<std::mutex> lock(mutex_);
    wake_.wait(lock, [this] { return stop_; });
    return false;
  }
  {
    std::ofstream log(StateDir(state_dir_).SentLog(), std::ios::app);
    log << local_id << "\n";
  }
  std::error_code ec;
  fs::remove(path, ec);
  std::lock_guard<std::mutex> lock(mutex_);
  if (!last_error_.empty()) {
    spdlog::info("registry: sending again (the last error, {}: {})", last_error_time_, last_error_);
    last_error_.clear();
    last_error_time_.clear();
  }
  ++(result.already_there ? already_there_ : sent_);
  --depth_;
  queued_ids_.erase(local_id);
  last_sent_time_ = drivers::UtcNowIso8601();
  if (result.already_there) {
    spdlog::info("registry: {} was there already (sent again after a crash)",
                 entry.value("key", ""));
  }
  return true;
}

void RegistryOutbox::Run() {
  RegistryDb& db = *db_;
  Reconcile();
  double retry_s = kFirstRetryS;
  auto last_contact = std::chrono::steady_clock::now() - kHeartbeat;
  const bool hold_after_commit = HoldAfterCommit();
  while (true) {
    bool reconcile = false;
    {
      std::unique_lock<std::mutex> lock(mutex_);
      if (stop_) return;
      added_ = false;
      reconcile = reconcile_due_;
      reconcile_due_ = false;
    }
    if (reconcile) Reconcile();
    const std::vector<fs::path> waiting = WaitingEntries(Dir());
    const bool heartbeat_due = std::chrono::steady_clock::now() - last_contact >= kHeartbeat;
    bool failed = false;
    if ((!waiting.empty() || heartbeat_due) && !db.connected()) {
      std::string error;
      if (db.Connect(options_, /*migrate=*/true, &error)) {
        std::lock_guard<std::mutex> lock(mutex_);
        connected_ = true;
        schema_ = db.schema_version();
        spdlog::info("registry: connected (schema {}), {} entr{} waiting", schema_, waiting.size(),
                     waiting.size() == 1 ? "y" : "ies");
      } else {
        NoteError(error);
        failed = true;
      }
    }
    for (const auto& path : failed ? std::vector<fs::path>{} : waiting) {
      {
        std::lock_guard<std::mutex> lock(mutex_);
        if (stop_) return;
      }
      try {
        if (!SendEntry(path.string(), hold_after_commit)) {
          failed = true;
          break;
        }
      } catch (const std::exception& e) {  // a malformed entry's JSON (nlohmann's type errors)
        Reject(path.string(), "", e.what());
      }
      last_contact = std::chrono::steady_clock::now();
    }
    if (!failed && waiting.empty() && heartbeat_due && db.connected()) {
      std::string error;
      if (db.TouchStation(station_, host_, &error)) {
        last_contact = std::chrono::steady_clock::now();
        std::lock_guard<std::mutex> lock(mutex_);
        last_error_.clear();
        last_error_time_.clear();
      } else {
        db.Close();
        NoteError(error);
        failed = true;
      }
    }
    if (!failed) {
      std::lock_guard<std::mutex> lock(mutex_);
      retry_s = kFirstRetryS;
      connected_ = db.connected();
    }
    std::unique_lock<std::mutex> lock(mutex_);
    if (failed) {
      // Backing off; a new entry does not shorten the wait (the database is away).
      wake_.wait_for(lock, std::chrono::duration<double>(retry_s), [this] { return stop_; });
      retry_s = std::min(retry_s * 2.0, options_.retry_max_s);
    } else {
      wake_.wait_for(lock, kHeartbeat, [this] { return stop_ || added_ || reconcile_due_; });
    }
  }
}

RegistryHandle::~RegistryHandle() = default;

const std::shared_ptr<RegistryOutbox>& RegistryHandle::Ensure(const RegistryOptions& r,
                                                              const std::string& state_dir) {
  const auto wanted = std::make_tuple(r.conninfo, r.password_file, r.station, r.retry_max_s,
                                      r.connect_timeout_s, state_dir);
  if (outbox_ && options_ == wanted) return outbox_;  // a reload that left it as it was
  if (outbox_) {
    // (The old station, which held it too, is gone.)
    std::thread([old = std::move(outbox_)]() mutable { old.reset(); }).detach();
  }
  outbox_.reset();
  if (!r.enabled()) return outbox_;
  auto outbox = std::make_shared<RegistryOutbox>(state_dir, r);
  std::string error;
  if (!outbox->Start(&error)) {
    spdlog::error("{}", error);
    return outbox_;
  }
  outbox_ = std::move(outbox);
  options_ = wanted;
  spdlog::info("registry: station '{}', outbox in {}/outbox", StationName(r.station), state_dir);
  return outbox_;
}

}  // namespace turncal::daemon
