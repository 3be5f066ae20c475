#pragma once
// Every place in turncald's state directory (docs/protocol.md "The state directory"), named once.
// The files' contents belong to their owners: the journal and the calibrations to
// daemon/state/persistence.h, the records of writes into devices to
// daemon/state/device_write_record.h, the registry's outbox to daemon/registry/registry_outbox.h.
//
//   journal.jsonl                      every captured pose record (appended, fsynced)
//   batch.json                         the session's batch: id, fixture, start (issue 38)
//   calibrations/DEVICE.MODEL.json     the active calibration
//   history/DEVICE.MODEL.vN.json       every earlier active calibration
//   noise/DEVICE.json                  the noise profile this session measured
//   sessions/UTCTIME[-N]/              earlier sessions' journals, noise profiles and batch files
//                                      (`reset`)
//   reports/DEVICE.html                the calibration report of the device
//   device_writes/DEVICE.json          the writes into the device in effect
//   device_writes/DEVICE.UTCTIME[-N].json  every write and restore
//   outbox/SEQ-....json                the registry's entries waiting to be sent
//   outbox/rejected/                   entries the registry refused for good
//   outbox/sent.log                    what the registry committed

#include <filesystem>
#include <string>

namespace turncal::daemon {

class StateDir {
 public:
  explicit StateDir(std::filesystem::path root) : root_(std::move(root)) {}

  const std::filesystem::path& root() const { return root_; }

  std::filesystem::path Journal() const { return root_ / "journal.jsonl"; }
  std::filesystem::path Batch() const { return root_ / "batch.json"; }

  std::filesystem::path CalibrationsDir() const { return root_ / "calibrations"; }
  std::filesystem::path ActiveCalibration(const std::string& device,
                                          const std::string& model) const;
  std::filesystem::path HistoryDir() const { return root_ / "history"; }
  std::filesystem::path HistoryCalibration(const std::string& device, const std::string& model,
                                           int version) const;

  std::filesystem::path NoiseDir() const { return root_ / "noise"; }
  std::filesystem::path NoiseProfile(const std::string& device) const;

  std::filesystem::path SessionsDir() const { return root_ / "sessions"; }

  std::filesystem::path ReportsDir() const { return root_ / "reports"; }
  std::filesystem::path Report(const std::string& device) const;

  std::filesystem::path DeviceWritesDir() const { return root_ / "device_writes"; }
  std::filesystem::path DeviceWriteRecord(const std::string& device) const;

  std::filesystem::path OutboxDir() const { return root_ / "outbox"; }
  std::filesystem::path OutboxRejectedDir() const { return OutboxDir() / "rejected"; }
  std::filesystem::path SentLog() const { return OutboxDir() / "sent.log"; }

 private:
  std::filesystem::path root_;
};

// The UTC time now as the state directory's files are stamped with it: 20261126T074148Z.
std::string UtcStamp();

// `dir`/PREFIX.STAMP.SUFFIX... made unique: dir/{prefix}{stamp}{suffix}, else with -2, -3, ...
// after the stamp (an empty prefix and suffix name a folder: sessions/STAMP-2).
std::filesystem::path UniqueStamped(const std::filesystem::path& dir, const std::string& prefix,
                                    const std::string& stamp, const std::string& suffix);

}  // namespace turncal::daemon
