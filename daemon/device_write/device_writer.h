#pragma once
// Writing a calibration into a device, and everything turncald keeps of it (issue 23,
// docs/protocol.md "Writing a calibration into the device"): the `device_write` request's plan;
// the write itself (a window of the device's output, the write on the device's worker -- idle,
// write, read back, save, resume, configure again --, a window after it, the verification by
// measurement, the record in the state directory and the reply); the re-expression of the
// device's output into the stored values the station's calibrations were made with; what each
// dialogue says the device holds; and the verification at the next captured pose of a write the
// device moved across.
//
// The service hands it the requests, every sample, every identity, every captured pose and a
// tick; the device writer answers through the hooks below and the request's reply. It runs on the
// event loop; nothing in it blocks (the write runs on the device's worker).
//
//   device_writer.cc          the request and its plan
//   device_writer_job.cc      a write under way: its windows, the write, its end, its timeout
//   device_writer_records.cc  the record at each dialogue, the verification at the next pose

#include <Eigen/Core>
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "core/modeling/measurement_model.h"
#include "core/sequencing/sample.h"
#include "core/sequencing/stillness.h"
#include "daemon/device/writable_device.h"
#include "daemon/device_write/write_verification.h"
#include "daemon/state/device_write_record.h"
#include "daemon/station/station.h"
#include "protocol/messages.h"

namespace turncal::daemon {

class DeviceWriter {
 public:
  struct Hooks {
    // The device of that name (null: none is configured).
    std::function<WritableDevice*(const std::string& device)> device;
    // The station's model MODEL of DEVICE (null: none, or no station), and the noise the device's
    // sequencer measured (null before it has).
    std::function<const MeasurementModel*(const std::string& device, const std::string& model)>
        model_of;
    std::function<const NoiseProfile*(const std::string& device)> noise_of;
    // Runs `work` on the loop after the current handler (a write cannot start inside the
    // decoder's sample callback: the write ends that decoder).
    std::function<void(std::function<void()> work)> post;
    // An event for the socket's watchers: DEVICE_WRITTEN, DEVICE_WRITE_VERIFIED.
    std::function<void(const nlohmann::json& event)> publish;
    // A history entry written (its "history" names the file), or completed by the verification
    // at a pose: the registry's outbox. May be empty.
    std::function<void(const std::string& device, const nlohmann::json& entry)> history_written;
    // The monotonic clock (the windows' timeout).
    std::function<std::int64_t()> now_ns;
  };
  // The answer to a request: the plan (dry run), an ERROR, or, at the end, DEVICE_WRITTEN. The
  // caller adds the request's id; the client may be gone by then.
  using Reply = std::function<void(nlohmann::json message)>;

  explicit DeviceWriter(Hooks hooks);
  ~DeviceWriter();

  // The state directory (empty: no write is possible) and the station's options (its sensor
  // class and models), at the start and after every reload.
  void Configure(std::string state_dir, StationOptions station);

  // A device_write request from a client of uid `uid`.
  void Request(const protocol::DeviceWriteArgs& args, int uid, Reply reply);

  // Every sample of every device, before the station sees it: the windows of a write under way.
  // Returns the sample as the station must see it: `sample` itself, or, after a write, the
  // device's output re-expressed (in *scratch) in the stored values its calibrations were made
  // with.
  const Sample& OnSample(const Sample& sample, Sample* scratch) {
    if (writes_.empty()) return sample;
    return OnSampleOfWrittenDevice(sample, scratch);
  }
  // A device's identity after a dialogue (what it holds): the record is reconciled with it.
  // Returns the identity the station records (with the stored values its calibrations see).
  nlohmann::json OnIdentity(const std::string& device, const nlohmann::json& identity);
  // Every POSE_CAPTURED event: a write that waits for the next captured pose is verified there.
  void OnPoseCaptured(const nlohmann::json& event);
  // The windows' timeout (a device that stopped sending during a write).
  void Tick(std::int64_t now_ns);

  // What is in effect for the device (null: no write recorded or read yet), and whether a write
  // under way or a verification at the next pose is pending.
  const DeviceWriteRecord* record(const std::string& device) const;
  bool writing(const std::string& device) const;
  bool verification_pending(const std::string& device) const;

 private:
  // A write under way: what was asked, the plan, the steps, the windows of the device's output
  // before and after, and the history entry being built.
  struct Job {
    Reply reply;
    protocol::DeviceWriteArgs args;
    nlohmann::json plan;  // as shown to the client
    std::vector<drivers::mip::StoredWriteStep> steps;
    bool save = false;
    std::string serial;
    int version = 0;
    StoredCalibration device_before;  // what the device holds now
    StoredCalibration device_after;   // what it holds once written
    StoredCalibration as_if;          // the stored values the station's calibrations see
    Eigen::VectorXd theta;            // the calibration written (a verification at a pose uses it)
    Eigen::MatrixXd covariance;
    // kStarting: the window before is full and the write is posted to the loop.
    enum class Phase { kBefore, kStarting, kWriting, kAfter } phase = Phase::kBefore;
    OutputWindow before, after;
    int window = 20;
    std::int64_t phase_started_ns = 0;
    WriteAllowance allowance;  // the wander between the windows
    nlohmann::json entry;      // the history entry
  };
  // A write whose verification waits for the next captured pose (the device moved across it).
  struct PoseCheck {
    std::string model;
    int version = 0;
    Eigen::VectorXd theta;  // the calibration written (it may not be the active one by then)
    Eigen::MatrixXd covariance;
    std::string history;   // its history entry's file, completed then
    nlohmann::json entry;  // that entry
  };
  // Per device: the writes in effect, a write under way, a verification waiting for a pose.
  struct Writes {
    std::optional<DeviceWriteRecord> record;  // device_writes/DEVICE.json
    bool reexpress = false;                   // the device holds record->in_device != as_if
    std::shared_ptr<Job> job;
    std::optional<PoseCheck> at_pose;
  };

  // device_writer.cc: the plan.
  bool PlanWrite(const WritableDevice& device, const std::optional<StoredCalibration>& actual,
                 const StoredCalibration& as_if_now, Job* job, std::vector<std::string>* refusals,
                 std::string* error);
  bool PlanRestore(const std::optional<StoredCalibration>& actual, Writes* writes, Job* job,
                   std::vector<std::string>* refusals, std::string* error);
  // device_writer_job.cc: the write under way.
  const Sample& OnSampleOfWrittenDevice(const Sample& sample, Sample* scratch);
  void OnWriteSample(Writes* writes, const Sample& sample);
  void VerifyAfterWrite(Writes* writes, const Sample& sample);
  void StartStoredWrite(const std::string& device);
  bool RecordPending(const std::string& device, Job* job);
  void OnStoredWriteDone(const std::string& device, const std::shared_ptr<Job>& job,
                         const drivers::mip::StoredWriteOutcome& outcome,
                         const nlohmann::json& identity, const std::string& configure_error);
  void FinishWrite(const std::string& device);
  // The device's report (report/device_writes.h shows the writes) written again.
  void RewriteReport(const std::string& device) const;

  Hooks hooks_;
  std::string state_dir_;
  StationOptions station_;
  std::map<std::string, Writes> writes_;  // by device name
};

}  // namespace turncal::daemon
