#pragma once
// How a write into a device is verified by measurement (issue 23, docs/protocol.md "Writing a
// calibration into the device"): the device's output over a window before and after the write,
// the bias's wander between them, and the comparison, right after the write or at the next pose.

#include <Eigen/Core>
#include <nlohmann/json.hpp>
#include <optional>

#include "core/estimation/pose_record.h"
#include "core/modeling/measurement_model.h"
#include "core/sequencing/sample.h"
#include "daemon/state/device_write_record.h"

namespace turncal::daemon {

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
