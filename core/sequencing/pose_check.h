#pragma once
// Does a pose's measured mean fit the pose the controller announced? (issue "Position
// sequencer": a wrong announcement must be rejected, not silently calibrated.) The prediction
// comes from the current calibration with its uncertainty, or -- before any calibration -- from
// the nominal parameters with an angle tolerance for what an uncalibrated, imperfectly mounted
// sensor may show.

#include <Eigen/Core>
#include <string>

#include "core/estimation/pose_record.h"
#include "core/modeling/measurement_model.h"

namespace turncal {

struct TriadPrediction {
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  // Of the prediction: calibration uncertainty, pose-to-pose offsets the calibrator allows, and
  // for nominal predictions the angle tolerance.
  Eigen::Matrix3d covariance = Eigen::Matrix3d::Zero();
};

// From an estimate: Predict(theta, pose) with covariance J C J^T + pose_offset_sigma^2 I (C the
// estimate's covariance, J the Jacobian at theta).
TriadPrediction PredictFromEstimate(const MeasurementModel& model, const Eigen::VectorXd& theta,
                                    const Eigen::MatrixXd& covariance, const TablePose& pose,
                                    double pose_offset_sigma);

// From the nominal parameters: isotropic uncertainty such that a measured direction
// `angle_tolerance_rad` away from the prediction sits at the rejection limit of CheckPoseMean
// with `false_alarm`.
TriadPrediction NominalPrediction(const MeasurementModel& model, const TablePose& pose,
                                  double angle_tolerance_rad, double false_alarm);

struct PoseFit {
  bool fits = true;
  double distance2 = 0.0;  // Mahalanobis distance^2 of measured - predicted
  double limit2 = 0.0;     // chi^2_3 quantile at 1 - false_alarm
  double angle_rad = 0.0;  // between measured and predicted
  std::string reason;      // when it does not fit
};

// Compares the measured mean (covariance of the mean: covariance / count) with the prediction.
PoseFit CheckPoseMean(const TriadStats& measured, const TriadPrediction& prediction,
                      double false_alarm, const char* triad_name);

}  // namespace turncal
