#include "tools/report_state_dir.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <set>
#include <sstream>

#include "daemon/state/atomic_file.h"
#include "daemon/state/persistence.h"
#include "daemon/state/state_dir.h"
#include "protocol/sequencer_json.h"

namespace turncal::tools {
namespace fs = std::filesystem;

namespace {

// DEVICE of DEVICE.MODEL.json (models have no dot in their names; devices may).
std::string DeviceOfFileName(const fs::path& file) {
  const std::string stem = file.stem().string();
  const auto dot = stem.rfind('.');
  return dot == std::string::npos ? stem : stem.substr(0, dot);
}

// A calibration document: JSON with "device" and "model".
bool ReadCalibrationFile(const fs::path& path, nlohmann::json* out, std::string* error) {
  if (!daemon::ReadJsonFile(path, out, error)) return false;
  if (!out->is_object() || !out->contains("device") || !(*out)["device"].is_string() ||
      !out->contains("model") || !(*out)["model"].is_string()) {
    *error = fmt::format("'{}' is not a calibration (no \"device\" and \"model\")", path.string());
    return false;
  }
  return true;
}

// The journal's records of `device`, in order, as written; empty when the file is absent.
std::vector<nlohmann::json> JournalRecords(const fs::path& journal, const std::string& device) {
  std::vector<daemon::JournalEntry> entries;
  int skipped = 0;
  std::string why;
  std::vector<nlohmann::json> records;
  if (!daemon::PoseJournal::LoadFile(journal.string(), &entries, &skipped, &why)) return records;
  for (auto& e : entries) {
    if (e.device == device && !e.is_motion()) records.push_back(std::move(e.record_json));
  }
  return records;
}

bool SamePoses(const nlohmann::json& poses, const std::vector<nlohmann::json>& records) {
  if (!poses.is_array() || poses.empty() || records.size() < poses.size()) return false;
  for (std::size_t i = 0; i < poses.size(); ++i) {
    if (!poses[i].is_object() || !records[i].contains("pose") || !records[i]["pose"].is_object()) {
      return false;
    }
    for (const char* key : {"phi_deg", "gamma_deg", "psi_deg"}) {
      const auto& a = poses[i].value(key, nlohmann::json());
      const auto& b = records[i]["pose"].value(key, nlohmann::json());
      if (!a.is_number() || !b.is_number() || std::abs(a.get<double>() - b.get<double>()) > 1e-6) {
        return false;
      }
    }
  }
  return true;
}

}  // namespace

bool ReadStateDirCalibrations(const std::string& state_dir, const std::string& device,
                              std::map<std::string, DeviceCalibrations>* out, std::string* error) {
  out->clear();
  const fs::path dir = daemon::StateDir(state_dir).CalibrationsDir();
  std::error_code ec;
  if (!fs::is_directory(dir, ec)) {
    *error = fmt::format("no calibrations found: '{}' is not a directory{}", dir.string(),
                         fs::is_directory(state_dir, ec) ? " (no model has passed its gate yet?)"
                                                         : "; is the state directory right?");
    return false;
  }
  std::vector<fs::path> files;
  for (fs::directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec)) {
    const fs::path& p = it->path();
    // Temporary files of an atomic write end in .tmp.PID, not .json.
    if (p.extension() == ".json" && p.filename().string()[0] != '.') files.push_back(p);
  }
  if (ec) {
    *error = fmt::format("cannot list '{}': {}", dir.string(), ec.message());
    return false;
  }
  std::sort(files.begin(), files.end());
  std::set<std::string> devices;
  for (const auto& f : files) devices.insert(DeviceOfFileName(f));
  if (files.empty()) {
    *error = fmt::format("no calibrations found in '{}'", dir.string());
    return false;
  }
  if (!device.empty() && !devices.count(device)) {
    std::string names;
    for (const auto& d : devices) names += (names.empty() ? "" : ", ") + d;
    *error = fmt::format("no calibration of device '{}' in '{}' (devices there: {})", device,
                         dir.string(), names);
    return false;
  }
  for (const auto& f : files) {
    if (!device.empty() && DeviceOfFileName(f) != device) continue;
    nlohmann::json calibration;
    if (!ReadCalibrationFile(f, &calibration, error)) return false;
    const std::string name = calibration["device"].get<std::string>();
    // The file name decides which device a calibration is (and so the report's file name): a
    // document that names another device is refused, not filed elsewhere.
    if (name != DeviceOfFileName(f)) {
      *error = fmt::format("'{}' names device '{}', but its file name says '{}'", f.string(), name,
                           DeviceOfFileName(f));
      return false;
    }
    DeviceCalibrations& d = (*out)[name];
    d.calibrations.push_back(std::move(calibration));
    d.paths.push_back(f.string());
  }
  return true;
}

std::string AttachJournalRecords(const std::string& state_dir, nlohmann::json* calibration) {
  nlohmann::json& c = *calibration;
  if (!c.contains("provenance") || !c["provenance"].is_object()) return "";
  nlohmann::json& provenance = c["provenance"];
  if (provenance.contains("records")) return "";
  const std::string device = c.value("device", "");
  const nlohmann::json poses = provenance.value("poses", nlohmann::json::array());
  // The current session's journal first, then archived sessions, newest first.
  const daemon::StateDir places(state_dir);
  std::vector<fs::path> journals = {places.Journal()};
  std::vector<fs::path> archived;
  std::error_code ec;
  for (fs::directory_iterator it(places.SessionsDir(), ec), end; !ec && it != end;
       it.increment(ec)) {
    archived.push_back(daemon::StateDir(it->path()).Journal());
  }
  std::sort(archived.rbegin(), archived.rend());
  journals.insert(journals.end(), archived.begin(), archived.end());
  for (const auto& journal : journals) {
    std::vector<nlohmann::json> records = JournalRecords(journal, device);
    if (!SamePoses(poses, records)) continue;
    records.resize(poses.size());
    provenance["records"] = records;
    return fmt::format("pose records taken from the journal '{}' (matched by table angles)",
                       journal.string());
  }
  return "the calibration carries no pose records and no journal holds its poses: residuals, "
         "convergence and observability are left out";
}

bool ReadDriftFile(const std::string& path, nlohmann::json* rows, std::string* error) {
  std::ifstream in(path);
  if (!in) {
    *error = fmt::format("--drift: cannot open {}", path);
    return false;
  }
  *rows = nlohmann::json::parse(in, nullptr, false);
  if (!rows->is_array() || (!rows->empty() && !(*rows)[0].contains("parameter"))) {
    *error = fmt::format("--drift: {} is not `turncal registry drift SERIAL --json` output", path);
    return false;
  }
  return true;
}

}  // namespace turncal::tools
