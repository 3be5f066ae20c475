#pragma once
// The state directory (issue "The daemon"): what must survive a crash.
//
//   journal.jsonl                  every captured pose record, one JSON line each, appended and
//                                  fsynced before the pose is used: a restart resumes the session;
//                                  in free mode also the magnetometer's new values in motion, a
//                                  line per batch {"device", "motion": [[t_host, t_device|null,
//                                  mx, my, mz, temp|null], ...]} (issue 37)
//   calibrations/DEVICE.MODEL.json the active calibration (schema 1), written atomically
//   history/DEVICE.MODEL.vN.json   every earlier active calibration
//   noise/DEVICE.json              the noise profile this session measured
//   sessions/UTCTIME/              earlier sessions' journals and noise profiles (`reset`)
//   reports/DEVICE.html            the calibration report of the device's active calibrations
//                                  (report/html.h), rewritten after activations
//   device_writes/                 what turncal wrote into the device
//   (daemon/state/device_write_record.h)
//
// A kill -9 can leave the journal's last line incomplete; loading skips it and says so.

#include <cstdio>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "core/estimation/free_motion.h"
#include "core/estimation/pose_record.h"
#include "core/sequencing/stillness.h"

namespace turncal::daemon {

struct JournalEntry {
  std::string device;
  PoseRecord record;
  nlohmann::json record_json;  // the record as the journal holds it
  // A batch of magnetometer values in motion (then `record` is empty and record_json null).
  std::vector<MotionValue> motion;
  bool is_motion() const { return !motion.empty(); }
};

class PoseJournal {
 public:
  ~PoseJournal();
  // Opens (creating the directory and file) for appending. False with a message.
  bool Open(const std::string& state_dir, std::string* error);
  // Appends one record and fsyncs it. False with a message (the entry may be missing or torn
  // then; the next Open ends a torn line).
  bool Append(const std::string& device, const PoseRecord& record, std::string* error);
  // Appends a batch of magnetometer values in motion (one line) and fsyncs it.
  bool AppendMotion(const std::string& device, const std::vector<MotionValue>& values,
                    std::string* error);
  // Every whole entry of the journal in `state_dir` (none when there is no journal). Lines that
  // do not parse (a torn last line) are counted in *skipped.
  static bool Load(const std::string& state_dir, std::vector<JournalEntry>* entries, int* skipped,
                   std::string* error);
  // The same of one journal file (an archived session's: sessions/UTCTIME/journal.jsonl).
  static bool LoadFile(const std::string& path, std::vector<JournalEntry>* entries, int* skipped,
                       std::string* error);

 private:
  bool AppendLine(const std::string& line, std::string* error);
  int fd_ = -1;
};

// Writes calibrations/DEVICE.MODEL.json atomically; the calibration it replaces is copied to
// history/ first. `calibration` must carry "version".
// noise/DEVICE.json: the noise profile measured in this session.
bool WriteNoiseProfile(const std::string& state_dir, const std::string& device,
                       const NoiseProfile& profile, std::string* error);
bool ReadNoiseProfile(const std::string& state_dir, const std::string& device,
                      NoiseProfile* profile);
bool ReadActiveCalibration(const std::string& state_dir, const std::string& device,
                           const std::string& model, nlohmann::json* calibration);
// `reset`: the session's journal and noise profiles move to sessions/UTCTIME/ (the active
// calibrations stay, and stay applied). *archived receives the folder ("" when there was nothing
// to archive). False with a message.
bool ArchiveSession(const std::string& state_dir, std::string* archived, std::string* error);

bool WriteActiveCalibration(const std::string& state_dir, const std::string& device,
                            const std::string& model, const nlohmann::json& calibration,
                            std::string* error);

// reports/DEVICE.html: the calibration report (report/html.h) of the device's active
// calibrations of `models`, written atomically. `generated_utc` is shown in its header. False
// with a message (no calibration of those models, a render or write failure).
bool WriteDeviceReport(const std::string& state_dir, const std::string& device,
                       const std::vector<std::string>& models, const std::string& generated_utc,
                       std::string* error);

}  // namespace turncal::daemon
