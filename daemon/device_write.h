#pragma once
// What turncald keeps of the writes into a device's stored calibration (issue 23,
// docs/protocol.md "Writing a calibration into the device"), and how a write is verified by
// measurement.
//
// In the state directory:
//   device_writes/DEVICE.json          what is in effect: the values the device holds, those the
//                                      last write or restore replaced, and the stored values the
//                                      station's calibrations see the device's output in
//                                      (`as_if`: what it held before turncal's first write;
//                                      `restore` writes them back)
//   device_writes/DEVICE.UTCTIME.json  every write and restore: the plan, every step, the
//                                      outcome, the verification (never rewritten)
//
// After a write the device outputs m' (its new stored values applied), while the station's poses
// and calibrations were made from its output m with `as_if` applied. turncald re-expresses every
// sample of the device in `as_if` (drivers/mip/mip_stored.h ReexpressMipOutput) before the
// station sees it, so the session goes on unchanged and the corrected stream is the calibration's
// correction of the device's new output; the `raw` stream shows what the device sends.

#include <Eigen/Core>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "core/estimation/pose_record.h"
#include "core/modeling/measurement_model.h"
#include "core/sequencing/sample.h"
#include "drivers/mip/mip_dialogue.h"

namespace turncal::daemon {

using drivers::mip::StoredCalibration;

bool SameStoredCalibration(const StoredCalibration& a, const StoredCalibration& b);

struct DeviceWriteRecord {
  std::string device, serial;
  std::string model;  // the calibration written last ("" after a restore to `as_if`)
  int version = 0;
  std::string time;             // UTC of the last operation
  std::string operation;        // "write" or "restore"
  StoredCalibration as_if;      // the stored values the station's calibrations see the output in
  StoredCalibration in_device;  // what the device holds after the last operation
  StoredCalibration replaced;   // what the last operation replaced (restore writes these back)
  bool saved = false;           // the last operation saved to non-volatile memory
  // A write since the device held `as_if` saved to non-volatile memory (a restore then saves
  // too, so that the device starts with `as_if` again).
  bool nonvolatile_changed = false;
  // What a write under way puts into the device (written before it starts): a turncald that
  // stops mid-write finds, at the device's next dialogue, whether the device holds these.
  std::optional<StoredCalibration> pending;
  // The re-expression is needed while the device holds other values than `as_if`.
  bool reexpress() const { return !SameStoredCalibration(in_device, as_if); }
};

nlohmann::json ToJson(const DeviceWriteRecord& record);
bool ParseDeviceWriteRecord(const nlohmann::json& j, DeviceWriteRecord* out, std::string* error);

// device_writes/DEVICE.json: *exists false (and true returned) when there is none. False with a
// message when it cannot be read or parsed.
bool ReadDeviceWriteRecord(const std::string& state_dir, const std::string& device,
                           DeviceWriteRecord* record, bool* exists, std::string* error);
bool WriteDeviceWriteRecord(const std::string& state_dir, const DeviceWriteRecord& record,
                            std::string* error);
// device_writes/DEVICE.UTCTIME.json (a suffix -2, -3 ... when that second has one); *path
// receives it.
bool WriteDeviceWriteHistory(const std::string& state_dir, const std::string& device,
                             const nlohmann::json& entry, std::string* path, std::string* error);

// Every entry of device_writes/DEVICE.UTCTIME.json, oldest first (unreadable ones are skipped).
std::vector<nlohmann::json> ReadDeviceWriteHistory(const std::string& state_dir,
                                                   const std::string& device);

// The mean and scatter of a device's output over a window of samples (per triad).
class OutputWindow {
 public:
  void Add(const Sample& s);
  int count() const { return n_; }
  // The mean time of the samples: the device's clock where every sample has it, else the host's.
  double MeanTimeS() const;
  // The mean sample (triads present in every sample), with the variance of the mean per axis.
  Sample Mean() const;
  std::optional<Eigen::Vector3d> MeanVariance(int triad) const;  // kTriadAcc, kTriadGyr, kTriadMag
  std::optional<Eigen::Matrix3d> MeanCovariance(int triad) const;

 private:
  struct Sums {
    int n = 0;
    Eigen::Vector3d sum = Eigen::Vector3d::Zero(), sum_sq = Eigen::Vector3d::Zero();
    Eigen::Matrix3d sum_outer = Eigen::Matrix3d::Zero();
    Eigen::Vector3d first = Eigen::Vector3d::Zero();  // sums are taken about the first value
  };
  Sums acc_, gyr_, mag_;
  int n_ = 0, n_device_time_ = 0;
  double t_device_sum_s_ = 0.0, t_host_sum_s_ = 0.0;
};

// What the verification allows for besides the two windows' scatter, per triad (kTriadAcc,
// kTriadGyr, kTriadMag): the 1 sigma of the bias's wander between the two windows. (The
// calibration's own sigma plays no part: the prediction is the output before the write
// re-expressed in the values written, which the device holds exactly.)
struct WriteAllowance {
  double wander_sigma[3] = {0.0, 0.0, 0.0};
};

// The 1 sigma of a Gauss-Markov bias's change over `dt_s` (instability `sigma`, correlation time
// `tau_s`): sigma sqrt(2 (1 - exp(-dt/tau))).
double WanderSigma(double sigma, double tau_s, double dt_s);

// A verification compares `axes` independent z's; it passes when every |z| is within the limit
// that puts its false alarms at kVerifyFalseAlarm in all (3.59 for 3 axes, 3.76 for 6, 3.87
// for 9).
inline constexpr double kVerifyFalseAlarm = 1e-3;
double VerifyZLimit(int axes);

// Verification by measurement: the device's output after the write (`after`, `written` applied)
// against the output predicted from the output before it (`before`, `replaced` applied): the
// before-mean re-expressed in the written values. Per written triad, per axis: the difference,
// its sigma (the two means' covariance, the before-window's carried through the re-expression,
// and `allowance`) and the z; it passes when every |z| <= VerifyZLimit(axes compared).
// {"pass","samples_before","samples_after","seconds_between","triads":{"acc":{"measured",
//  "predicted","difference","sigma","sigma_noise","sigma_wander","z","unit"},...},"summary"}
nlohmann::json VerifyWrite(const OutputWindow& before, const OutputWindow& after,
                           const StoredCalibration& replaced, const StoredCalibration& written,
                           const WriteAllowance& allowance);

// Whether a window's scatter says the device moved: any axis of `triad` scattering more than
// `factor` times its per-sample noise `sigma` (false without one).
bool WindowMoved(const OutputWindow& window, int triad, const std::optional<Eigen::Vector3d>& sigma,
                 double factor = 3.0);

// Verification at a captured pose, when the table moved across the write: the pose's measured
// mean of `model`'s triad against the calibration's prediction (model.Predict(theta, pose)), both
// re-expressed from `as_if` (the station's) into the device's output with `in_device` applied --
// what the device reads, uncorrected, against what the calibration predicted. Per axis: the
// difference, sigma (the record mean's, the prediction's from `covariance`, `wander_sigma`) and z;
// it passes when every |z| <= VerifyZLimit(3). The same shape as VerifyWrite's, with "pose".
nlohmann::json VerifyAtPose(const MeasurementModel& model, const Eigen::VectorXd& theta,
                            const Eigen::MatrixXd& covariance, const PoseRecord& record,
                            const StoredCalibration& as_if, const StoredCalibration& in_device,
                            double wander_sigma);

}  // namespace turncal::daemon
