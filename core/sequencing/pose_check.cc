#include "core/sequencing/pose_check.h"

#include <fmt/format.h>

#include <Eigen/Cholesky>
#include <boost/math/distributions/chi_squared.hpp>
#include <cmath>

namespace turncal {
namespace {

double Chi2Limit3(double false_alarm) {
  return boost::math::quantile(boost::math::complement(boost::math::chi_squared(3.0), false_alarm));
}

}  // namespace

TriadPrediction PredictFromEstimate(const MeasurementModel& model, const Eigen::VectorXd& theta,
                                    const Eigen::MatrixXd& covariance, const TablePose& pose,
                                    double pose_offset_sigma) {
  TriadPrediction p;
  Jacobian3 j(3, model.num_parameters());
  p.mean = model.Predict(theta, pose, &j);
  // Undetermined parameters (infinite sigma) make no statement about this pose.
  Eigen::MatrixXd c = covariance;
  if (!c.allFinite()) c = c.unaryExpr([](double v) { return std::isfinite(v) ? v : 0.0; });
  p.covariance = j * c * j.transpose();
  p.covariance += pose_offset_sigma * pose_offset_sigma * Eigen::Matrix3d::Identity();
  return p;
}

TriadPrediction NominalPrediction(const MeasurementModel& model, const TablePose& pose,
                                  double angle_tolerance_rad, double false_alarm) {
  TriadPrediction p;
  p.mean = model.Predict(model.nominal(), pose);
  const double radius = p.mean.norm() * std::sin(angle_tolerance_rad);
  p.covariance = Eigen::Matrix3d::Identity() * radius * radius / Chi2Limit3(false_alarm);
  return p;
}

PoseFit CheckPoseMean(const TriadStats& measured, const TriadPrediction& prediction,
                      double false_alarm, const char* triad_name) {
  PoseFit fit;
  Eigen::Matrix3d s = prediction.covariance;
  if (measured.count > 0) s += SampleMeanCovariance(measured);
  const Eigen::Vector3d d = measured.mean - prediction.mean;
  fit.limit2 = Chi2Limit3(false_alarm);
  const Eigen::LDLT<Eigen::Matrix3d> ldlt(s);
  fit.distance2 = ldlt.info() == Eigen::Success && ldlt.isPositive()
                      ? d.dot(ldlt.solve(d))
                      : std::numeric_limits<double>::infinity();
  const double norms = measured.mean.norm() * prediction.mean.norm();
  fit.angle_rad = norms > 0
                      ? std::acos(std::clamp(measured.mean.dot(prediction.mean) / norms, -1.0, 1.0))
                      : 0.0;
  fit.fits = fit.distance2 <= fit.limit2;
  if (!fit.fits) {
    fit.reason = fmt::format(
        "the {} mean does not fit the commanded pose: {:.2f} deg from the predicted direction, "
        "|measured| {:.4g} vs predicted {:.4g} (distance^2 {:.3g} > {:.1f}, chi^2_3 at {:.0e}); "
        "wrong announcement?",
        triad_name, fit.angle_rad * 180 / M_PI, measured.mean.norm(), prediction.mean.norm(),
        fit.distance2, fit.limit2, false_alarm);
  }
  return fit;
}

}  // namespace turncal
