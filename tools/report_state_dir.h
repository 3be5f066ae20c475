#pragma once
// Reading a state directory's active calibrations for `turncal report` (daemon/state/persistence.h:
// STATE_DIR/calibrations/DEVICE.MODEL.json), without the daemon.

#include <map>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

namespace turncal::tools {

struct DeviceCalibrations {
  std::vector<nlohmann::json> calibrations;  // one per model
  std::vector<std::string> paths;            // the files they came from
};

// Every device's calibrations by device name; only `device`'s when it is not empty. False with
// a message when the folder cannot be listed, a file cannot be read, is not JSON or does not
// name its device and model, when there is no calibration at all, or none of `device` (the
// message lists the devices there are).
bool ReadStateDirCalibrations(const std::string& state_dir, const std::string& device,
                              std::map<std::string, DeviceCalibrations>* out, std::string* error);

// A calibration written before calibrations carried their pose records (provenance.records):
// the records are taken from the pose journal (STATE_DIR/journal.jsonl, else an archived
// session's) when its entries for the device have the calibration's poses, in order. Returns
// where they came from, or why there are none; "" when the calibration has its records.
std::string AttachJournalRecords(const std::string& state_dir, nlohmann::json* calibration);

// A file of `turncal registry drift SERIAL --json` (the unit's drift, for the report's and the
// certificate's drift sections). False with a message when it cannot be read or is not that.
bool ReadDriftFile(const std::string& path, nlohmann::json* rows, std::string* error);

}  // namespace turncal::tools
