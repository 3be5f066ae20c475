#include "report/analysis.h"

#include <fmt/format.h>

#include <Eigen/LU>
#include <algorithm>
#include <cmath>

namespace turncal::report {
namespace {

const TriadStats* TriadOf(const MeasurementModel& model, const PoseRecord& record) {
  const auto& triad = model.sensor() == SensorKind::kAccelerometer ? record.acc : record.mag;
  return triad ? &*triad : nullptr;
}

Eigen::Vector3d Rms(const std::vector<Eigen::Vector3d>& v) {
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  for (const auto& r : v) sum += r.cwiseAbs2();
  return v.empty() ? sum : Eigen::Vector3d((sum / static_cast<double>(v.size())).cwiseSqrt());
}

double RmsTotal(const Eigen::Vector3d& rms_axis) { return std::sqrt(rms_axis.squaredNorm() / 3); }

// The reference vector in the nominal case frame: M C_p^q R3(beta) v.
std::vector<Eigen::Vector3d> ReferenceDirections(const protocol::CalibrationDocument& doc) {
  const MeasurementModel& model = *doc.measurement_model;
  const bool accel = model.sensor() == SensorKind::kAccelerometer;
  const Eigen::Vector3d v_ned = accel ? doc.context.reference.g_ned : doc.context.reference.B_ned;
  const int beta_index = model.index_of("beta");
  const double beta_rad = beta_index >= 0 ? doc.theta[beta_index] : 0.0;
  std::vector<Eigen::Vector3d> out;
  for (const TablePose& pose : doc.poses) {
    const Eigen::Vector3d v_sensor =
        doc.context.mounting * pose.C_p_q() * C_ned_p(beta_rad) * v_ned;
    out.push_back(v_sensor.normalized());
  }
  return out;
}

}  // namespace

ModelAnalysis AnalyzeCalibration(const protocol::CalibrationDocument& doc) {
  ModelAnalysis a;
  const MeasurementModel& model = *doc.measurement_model;
  a.reference_dir_sensor = ReferenceDirections(doc);
  const Eigen::VectorXd nominal = model.nominal();

  // One calibrator, fed pose by pose as the station fed it: the convergence series, then the
  // weights of every pose for the residuals' error bars and the observability analysis.
  CalibratorOptions options = doc.calibrator;
  options.model = model.name();
  options.context = doc.context;
  Calibrator calibrator(options);
  const int identifiable = model.num_parameters() - model.gauge_dimension();
  const int first_k = (identifiable + 2) / 3;
  Estimate last;
  for (std::size_t i = 0; i < doc.records.size(); ++i) {
    const PoseRecord& record = doc.records[i];
    const TriadStats* triad = TriadOf(model, record);
    if (triad == nullptr || !calibrator.add_pose(record, nullptr)) continue;
    const Eigen::Vector3d measured = triad->mean;
    a.residuals.pose_index.push_back(static_cast<int>(i));
    a.residuals.before.push_back(measured - model.Predict(nominal, record.pose));
    a.residuals.after.push_back(measured - model.Predict(doc.theta, record.pose));
    const int k = calibrator.num_poses();
    if (k < first_k) continue;
    last = calibrator.solve();
    a.convergence.k.push_back(k);
    a.convergence.sigma.push_back(
        last.ok ? last.sigma : Eigen::VectorXd::Constant(model.num_parameters(), std::nan("")));
  }
  a.has_records = !a.residuals.after.empty();
  if (!a.has_records) {
    a.no_records_reason = doc.records.empty() ? "the calibration carries no pose measurements"
                                              : fmt::format("no record carries the {} triad",
                                                            ToString(model.sensor()));
    a.convergence.note = a.no_records_reason;
    return a;
  }
  PoseResiduals& r = a.residuals;
  for (const WeightedPose& w : calibrator.weighted_poses()) {
    const Eigen::Matrix3d information = w.sqrt_information.transpose() * w.sqrt_information;
    r.sigma_mean.push_back(information.inverse().diagonal().cwiseMax(0.0).cwiseSqrt());
  }
  r.rms_before = Rms(r.before);
  r.rms_after = Rms(r.after);
  r.rms_before_total = RmsTotal(r.rms_before);
  r.rms_after_total = RmsTotal(r.rms_after);

  if (!last.ok) {
    a.convergence.note = "the re-solve with every pose failed: " + last.error;
  } else {
    double worst = 0.0;
    for (Eigen::Index i = 0; i < doc.theta.size(); ++i) {
      const double s = std::isfinite(doc.sigma[i]) ? doc.sigma[i] : last.sigma[i];
      if (std::isfinite(s) && s > 0)
        worst = std::max(worst, std::abs(last.theta[i] - doc.theta[i]) / s);
    }
    a.convergence.resolve_max_z = worst;
    if (worst > 0.1) {
      a.convergence.note = fmt::format(
          "the re-solve with every pose differs from the stored estimate by up to {:.2g} sigma "
          "(different noise settings or poses than the station's?)",
          worst);
    }
  }
  a.observability =
      AnalyzeData(model, doc.theta, calibrator.weighted_poses(), ObservabilityOptions{});
  a.observability_done = true;
  return a;
}

}  // namespace turncal::report
