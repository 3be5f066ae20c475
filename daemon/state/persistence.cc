#include "daemon/state/persistence.h"

#include "daemon/state/batch_file.h"

#include <fcntl.h>
#include <fmt/format.h>
#include <unistd.h>

#include <cerrno>
#include <cmath>
#include <cstring>
#include <ctime>
#include <filesystem>
#include <fstream>

#include "daemon/state/atomic_file.h"
#include "daemon/state/device_write_record.h"
#include "daemon/state/state_dir.h"
#include "protocol/sequencer_json.h"
#include "report/html.h"

namespace turncal::daemon {
namespace fs = std::filesystem;

PoseJournal::~PoseJournal() {
  if (fd_ >= 0) ::close(fd_);
}

bool PoseJournal::Open(const std::string& state_dir, std::string* error) {
  std::error_code ec;
  fs::create_directories(state_dir, ec);
  if (ec) {
    *error = fmt::format("cannot create the state directory '{}': {}", state_dir, ec.message());
    return false;
  }
  const std::string path = StateDir(state_dir).Journal().string();
  fd_ = ::open(path.c_str(), O_RDWR | O_APPEND | O_CREAT | O_CLOEXEC, 0644);
  if (fd_ < 0) {
    *error = fmt::format("cannot open the journal '{}': {}", path, std::strerror(errno));
    return false;
  }
  // A line torn by a crash or a full disk is ended here, so it spoils only itself (Load skips
  // it), not the next record.
  const off_t size = ::lseek(fd_, 0, SEEK_END);
  char last = '\n';
  if (size > 0 && ::pread(fd_, &last, 1, size - 1) == 1 && last != '\n') {
    if (::write(fd_, "\n", 1) != 1 || ::fsync(fd_) != 0) {
      *error = fmt::format("cannot repair the journal '{}': {}", path, std::strerror(errno));
      ::close(fd_);
      fd_ = -1;
      return false;
    }
  }
  return true;
}

bool PoseJournal::Append(const std::string& device, const PoseRecord& record, std::string* error) {
  return AppendLine(
      nlohmann::json{{"device", device}, {"record", protocol::ToJson(record)}}.dump() + "\n",
      error);
}

namespace {
nlohmann::json OptionalNumber(const std::optional<double>& v) {
  return v && std::isfinite(*v) ? nlohmann::json(*v) : nlohmann::json();
}

bool ParseMotion(const nlohmann::json& j, std::vector<MotionValue>* out) {
  if (!j.is_array() || j.empty()) return false;
  for (const auto& row : j) {
    if (!row.is_array() || row.size() != 6) return false;
    MotionValue v;
    for (int k : {0, 2, 3, 4}) {
      if (!row[static_cast<std::size_t>(k)].is_number()) return false;
    }
    v.t_host_s = row[0].get<double>();
    if (row[1].is_number()) v.t_device_s = row[1].get<double>();
    v.mag = {row[2].get<double>(), row[3].get<double>(), row[4].get<double>()};
    if (row[5].is_number()) v.temp_c = row[5].get<double>();
    out->push_back(v);
  }
  return true;
}
}  // namespace

bool PoseJournal::AppendMotion(const std::string& device, const std::vector<MotionValue>& values,
                               std::string* error) {
  nlohmann::json rows = nlohmann::json::array();
  for (const MotionValue& v : values) {
    rows.push_back({v.t_host_s, OptionalNumber(v.t_device_s), v.mag.x(), v.mag.y(), v.mag.z(),
                    OptionalNumber(v.temp_c)});
  }
  return AppendLine(nlohmann::json{{"device", device}, {"motion", rows}}.dump() + "\n", error);
}

bool PoseJournal::AppendLine(const std::string& line, std::string* error) {
  if (fd_ < 0) {
    *error = "the journal is not open";
    return false;
  }
  // Unbuffered: a failed write leaves nothing behind in a buffer to appear later.
  std::size_t done = 0;
  while (done < line.size()) {
    const ssize_t n = ::write(fd_, line.data() + done, line.size() - done);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) {
      *error = fmt::format("cannot append to the journal: {}",
                           n < 0 ? std::strerror(errno) : "nothing written");
      return false;
    }
    done += static_cast<std::size_t>(n);
  }
  if (::fsync(fd_) != 0) {
    *error = fmt::format("cannot append to the journal: fsync: {}", std::strerror(errno));
    return false;
  }
  return true;
}

bool PoseJournal::Load(const std::string& state_dir, std::vector<JournalEntry>* entries,
                       int* skipped, std::string* error) {
  return LoadFile(StateDir(state_dir).Journal().string(), entries, skipped, error);
}

bool PoseJournal::LoadFile(const std::string& path, std::vector<JournalEntry>* entries,
                           int* skipped, std::string* error) {
  entries->clear();
  *skipped = 0;
  std::ifstream in(path, std::ios::binary);
  if (!in) {
    if (fs::exists(path)) {
      *error = fmt::format("cannot read the journal '{}'", path);
      return false;
    }
    return true;
  }
  std::string line;
  while (std::getline(in, line)) {
    const auto j = nlohmann::json::parse(line, nullptr, false);
    JournalEntry e;
    std::string why;
    if (!j.is_discarded() && j.is_object() && j.contains("motion") && j.contains("device") &&
        j["device"].is_string()) {
      if (!ParseMotion(j["motion"], &e.motion)) {
        ++*skipped;
        continue;
      }
      e.device = j["device"].get<std::string>();
      entries->push_back(std::move(e));
      continue;
    }
    if (j.is_discarded() || !j.is_object() || !j.contains("device") || !j["device"].is_string() ||
        !j.contains("record") || !protocol::ParsePoseRecord(j["record"], &e.record, &why)) {
      ++*skipped;
      continue;
    }
    e.device = j["device"].get<std::string>();
    e.record_json = j["record"];
    entries->push_back(std::move(e));
  }
  return true;
}

bool WriteNoiseProfile(const std::string& state_dir, const std::string& device,
                       const NoiseProfile& profile, std::string* error) {
  std::error_code ec;
  const fs::path dir = StateDir(state_dir).NoiseDir();
  fs::create_directories(dir, ec);
  if (ec) {
    *error = fmt::format("cannot create '{}': {}", dir.string(), ec.message());
    return false;
  }
  return WriteFileAtomically(StateDir(state_dir).NoiseProfile(device).string(),
                             protocol::ToJson(profile).dump(2) + "\n", error);
}

bool ReadNoiseProfile(const std::string& state_dir, const std::string& device,
                      NoiseProfile* profile) {
  std::ifstream in(StateDir(state_dir).NoiseProfile(device), std::ios::binary);
  if (!in) return false;
  const auto j = nlohmann::json::parse(in, nullptr, false);
  std::string error;
  return !j.is_discarded() && protocol::ParseNoiseProfile(j, profile, &error);
}

bool ReadActiveCalibration(const std::string& state_dir, const std::string& device,
                           const std::string& model, nlohmann::json* calibration) {
  std::ifstream in(StateDir(state_dir).ActiveCalibration(device, model), std::ios::binary);
  if (!in) return false;
  *calibration = nlohmann::json::parse(in, nullptr, false);
  return !calibration->is_discarded() && calibration->is_object();
}

bool WriteActiveCalibration(const std::string& state_dir, const std::string& device,
                            const std::string& model, const nlohmann::json& calibration,
                            std::string* error) {
  std::error_code ec;
  const StateDir places(state_dir);
  const fs::path dir = places.CalibrationsDir();
  const fs::path history = places.HistoryDir();
  fs::create_directories(dir, ec);
  if (!ec) fs::create_directories(history, ec);
  if (ec) {
    *error = fmt::format("cannot create '{}': {}", dir.string(), ec.message());
    return false;
  }
  const fs::path path = places.ActiveCalibration(device, model);
  // The calibration being replaced goes to the history first (a copy: until the new one is in
  // place, the old one stays active).
  nlohmann::json old;
  if (ReadActiveCalibration(state_dir, device, model, &old)) {
    const int version = old.contains("version") && old["version"].is_number_integer()
                            ? old["version"].get<int>()
                            : 0;
    if (!WriteFileAtomically(places.HistoryCalibration(device, model, version).string(),
                             old.dump(2) + "\n", error)) {
      return false;
    }
  }
  return WriteFileAtomically(path.string(), calibration.dump(2) + "\n", error);
}

bool WriteDeviceReport(const std::string& state_dir, const std::string& device,
                       const std::vector<std::string>& models, const std::string& generated_utc,
                       std::string* error) {
  std::vector<nlohmann::json> calibrations;
  for (const auto& model : models) {
    nlohmann::json c;
    if (ReadActiveCalibration(state_dir, device, model, &c)) calibrations.push_back(std::move(c));
  }
  if (calibrations.empty()) {
    *error = fmt::format("report of {}: no active calibration in {}", device, state_dir);
    return false;
  }
  std::string html, why;
  report::ReportOptions options;
  options.source = state_dir;
  options.generated_utc = generated_utc;
  options.device_writes = ReadDeviceWriteHistory(state_dir, device);
  options.batch = ReadBatchStatus(state_dir);
  if (!report::RenderReportHtml(calibrations, options, &html, &why)) {
    *error = fmt::format("report of {}: {}", device, why);
    return false;
  }
  const fs::path dir = StateDir(state_dir).ReportsDir();
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec) {
    *error = fmt::format("report of {}: cannot create {}: {}", device, dir.string(), ec.message());
    return false;
  }
  return WriteFileAtomically(StateDir(state_dir).Report(device).string(), html, error);
}

bool ArchiveSession(const std::string& state_dir, std::string* archived, std::string* error) {
  archived->clear();
  const StateDir places(state_dir);
  std::error_code ec;
  const bool journal = fs::exists(places.Journal(), ec);
  const bool noise = fs::exists(places.NoiseDir(), ec);
  const bool batch = fs::exists(places.Batch(), ec);
  if (!journal && !noise && !batch) return true;
  const fs::path target = UniqueStamped(places.SessionsDir(), "", UtcStamp(), "");
  const StateDir archive(target);
  fs::create_directories(target, ec);
  if (!ec && journal) fs::rename(places.Journal(), archive.Journal(), ec);
  if (!ec && noise) fs::rename(places.NoiseDir(), archive.NoiseDir(), ec);
  if (!ec && batch) fs::rename(places.Batch(), archive.Batch(), ec);
  if (ec) {
    *error = fmt::format("cannot archive the session to '{}': {}", target.string(), ec.message());
    return false;
  }
  *archived = target.string();
  return true;
}

}  // namespace turncal::daemon
