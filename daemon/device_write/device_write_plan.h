#pragma once
// What a calibration writes into a MIP device's stored calibration, before anything is written
// (issue 23; docs/protocol.md "Writing a calibration into the device").
//
// The device applies its stored values before it outputs scaled data: accel out = M (raw - b_a)
// (g), gyro out = M (raw - b_g) (rad/s), mag out = M S (raw - h) (Gauss), M its sensor-to-vehicle
// transform (0x33; the identity when it has none). turncal calibrated from that output (the values
// then stored are in the calibration's provenance), so the values to write are the composition of
// the calibration with what is stored. Every model's correction of a sample is affine,
// y = A m + c (found from the model's own Correct(), checked at a fifth point); its bias in the
// measurement is b = -A^-1 c, and A = R P (polar decomposition: R a rotation, P symmetric positive
// definite). Then:
//
// - accelerometer, gyroscope: the device holds a bias only. Write b_old + M^-1 b (the
//   accelerometer's in g); the new output is m' = m - b, and the scale factors and misalignments
//   (A) have no MIP command and stay in turncald's stream: y = A m'.
// - magnetometer: write the soft iron M^-1 P M S_old and the hard iron h_old + S_old^-1 M^-1 b;
//   the new output is m' = P (m - b), and the rotation R (between the magnetometer and the frame
//   the calibration corrects into) stays in the stream: y = R m'.
// - with `transform`, also M_new = R M: the device's every output turns by R, the new output of
//   the calibrated triad is R (m - b) (accelerometer, gyroscope: y = R P R^T m'; magnetometer:
//   y = m'), and turncald re-expresses the other triads' output for their calibrations.
//
// The values are rounded to f32, as the device holds them; their 1 sigma comes from the
// calibration's covariance through the composition's Jacobian (central differences).
//
// Refused, with the reason: a calibration that has not passed its gate, one made on another
// device (serial), one made while the device stored other values than it has now, an Xbus or GX2
// device (no public command writes a user calibration), a quantity the device has no command for
// (it answered NACK 1 "unknown command" when configured), a correction that is not affine.

#include <cstdint>
#include <functional>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "core/modeling/free_model.h"
#include "core/modeling/measurement_model.h"
#include "drivers/device_spec.h"
#include "drivers/mip/mip_dialogue.h"

namespace turncal::daemon {

// A calibration's correction of its triad, as the plan needs it: from a pose model
// (core/modeling/measurement_model.h) or a free one (core/modeling/free_model.h: accel9, gyro9,
// gyro9g, magellipsoid, magsphere).
struct TriadCorrection {
  std::string name;  // the model's
  SensorKind sensor = SensorKind::kAccelerometer;
  double scale = 1.0;  // the excitation's magnitude: where the correction is probed
  std::function<Eigen::Vector3d(const Eigen::VectorXd& theta, const Eigen::Vector3d& m)> correct;
  // What else the model corrects that stays in the stream (a gyroscope's g-sensitivity); "" none.
  std::string also_in_stream;
};
TriadCorrection CorrectionOf(const MeasurementModel& model);
// `scale`: the excitation's magnitude (gravity, the field's; 1 when not known).
TriadCorrection CorrectionOf(const FreeModel& model, double scale);

// y = A m + c.
struct AffineCorrection {
  Eigen::Matrix3d A = Eigen::Matrix3d::Identity();
  Eigen::Vector3d c = Eigen::Vector3d::Zero();
};

// The affine form of `model`'s correction at `theta`, from Correct() at zero and the three axes
// scaled to the excitation's magnitude; false with a message when a fifth point is off it by
// more than 1e-9 relative (a correction that is not affine) or A is singular.
bool AffineCorrectionOf(const MeasurementModel& model, const Eigen::VectorXd& theta,
                        AffineCorrection* out, std::string* error);
bool AffineCorrectionOf(const TriadCorrection& correction, const Eigen::VectorXd& theta,
                        AffineCorrection* out, std::string* error);

// One stored quantity: what the device holds and what to write.
struct StoredWrite {
  std::string quantity;          // accel_bias_g, gyro_bias_radps, hard_iron_gauss, soft_iron,
                                 // sensor_to_vehicle
  std::uint8_t descriptor = 0;   // 0x37, 0x38, 0x3A, 0x3B, 0x33
  std::vector<double> stored;    // now in the device (3, or 9 row-major)
  std::vector<double> to_write;  // rounded to f32
  std::vector<double> sigma;     // 1 sigma of to_write (NaN without a covariance)
  std::string unit;              // g, rad/s, Gauss, "" (the matrix)
};

// A list of numbers as JSON, a non-finite one as null.
nlohmann::json JsonNumbers(const std::vector<double>& values);

struct DeviceWritePlan {
  std::string device, model, serial;
  int version = 0;
  std::vector<StoredWrite> writes;
  std::vector<std::string> refusals;  // empty: it may be written
  // What the device cannot hold, with what turncald keeps correcting in its stream.
  std::vector<std::string> kept_in_stream;
  // The expected change of the device's output, per triad, in words with numbers.
  std::vector<std::string> changes;
  // The stream's correction of the device's output once written: y = stream.A m' + stream.c.
  AffineCorrection stream;
  bool ok() const { return refusals.empty(); }
};

struct DeviceWriteRequest {
  std::string device;
  drivers::Protocol protocol = drivers::Protocol::kMip;
  std::string serial_now;                      // the connected device's serial
  drivers::mip::StoredCalibration stored_now;  // what it holds now (read at configuration)
  // The calibration: a pose model's, or (when `model` is null) any other correction's.
  const MeasurementModel* model = nullptr;
  std::optional<TriadCorrection> correction;
  Eigen::VectorXd theta;
  Eigen::MatrixXd covariance;  // empty: no sigma
  int version = 0;
  bool gate_passed = false;
  std::string serial_then;                                     // provenance.device_identity.serial
  std::optional<drivers::mip::StoredCalibration> stored_then;  // its stored_calibration
  // Also write the sensor-to-vehicle transform (0x33): the rotation R of the calibration's
  // correction A = R P, composed with the stored one (M_new = R M_old), so that the device
  // outputs in the frame the calibration corrects into. Off by default: it turns every output.
  bool transform = false;
};

DeviceWritePlan PlanDeviceWrite(const DeviceWriteRequest& request);

// provenance.device_identity.stored_calibration as recorded (live_device.cc); nullopt when the
// identity has none (a replay, an Xbus device).
std::optional<drivers::mip::StoredCalibration> StoredCalibrationFromIdentity(
    const nlohmann::json& identity);

nlohmann::json ToJson(const DeviceWritePlan& plan);

}  // namespace turncal::daemon
