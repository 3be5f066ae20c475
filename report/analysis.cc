#include "report/analysis.h"

#include <fmt/format.h>

#include <Eigen/Eigenvalues>
#include <Eigen/LU>
#include <algorithm>
#include <cmath>

namespace turncal::report {
namespace {

// 1 sigma of every parameter from the weighted poses' Fisher information at theta; infinite for
// a parameter the information leaves undetermined (a null direction of the column-scaled
// information touching it by more than 1e-3).
Eigen::VectorXd FisherSigma(const MeasurementModel& model, const Eigen::VectorXd& theta,
                            const std::vector<WeightedPose>& poses) {
  const int n = model.num_parameters();
  const Eigen::VectorXd scale = ParameterScales(model);
  // Each record's whitened Jacobian (a move's from its own residual).
  const Eigen::MatrixXd Jw = WhitenedJacobian(model, theta, poses) * scale.asDiagonal();
  const Eigen::MatrixXd info = Jw.transpose() * Jw;
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(info);
  const Eigen::VectorXd lambda = eig.eigenvalues();
  const double top = lambda.maxCoeff();
  Eigen::VectorXd var = Eigen::VectorXd::Zero(n);
  Eigen::VectorXd undetermined = Eigen::VectorXd::Zero(n);
  for (int k = 0; k < n; ++k) {
    const Eigen::VectorXd v = eig.eigenvectors().col(k);
    if (!(top > 0) || lambda[k] <= 1e-12 * top) {
      undetermined = undetermined.cwiseMax(v.cwiseAbs());
    } else {
      var += v.cwiseAbs2() / lambda[k];
    }
  }
  Eigen::VectorXd sigma(n);
  for (int j = 0; j < n; ++j) {
    sigma[j] = undetermined[j] > 1e-3 ? INFINITY : std::sqrt(var[j]) * scale[j];
  }
  return sigma;
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
  if (model.sensor() == SensorKind::kGyroscope) {
    // The inertial rate's direction: a rate segment's turning axis, a static pose's Earth rate.
    for (const TablePose& pose : doc.poses) {
      const Eigen::Vector3d w =
          pose.MeanC_p_q() * EarthRateNed(doc.context.reference) + pose.TableRate_q();
      out.push_back((doc.context.mounting * w).normalized());
    }
    return out;
  }
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
    const TriadStats* triad = TriadFor(model.sensor(), record);
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
    if (w.raw_residual) continue;  // a move (the residuals are the poses')
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
  const std::vector<WeightedPose> weighted = calibrator.weighted_poses();
  a.observability = AnalyzeData(model, doc.theta, weighted, ObservabilityOptions{});
  a.observability_done = true;
  if (model.sensor() == SensorKind::kGyroscope) {
    std::vector<WeightedPose> still, rate, moves;
    for (const WeightedPose& w : weighted) {
      (w.raw_residual ? moves : w.pose.is_rate() ? rate : still).push_back(w);
    }
    const std::pair<const char*, const std::vector<WeightedPose>*> sources[] = {
        {"static poses", &still}, {"rate segments", &rate}, {"moves", &moves}};
    SourceSigmas src;
    for (const auto& [name, list] : sources) {
      if (list->empty()) continue;
      src.source.push_back(name);
      src.records.push_back(static_cast<int>(list->size()));
      src.sigma.push_back(FisherSigma(model, doc.theta, *list));
    }
    if (src.source.size() >= 2) {
      src.sigma_all = FisherSigma(model, doc.theta, weighted);
      a.sources = std::move(src);
    }
    if (!rate.empty()) a.linearity = AnalyzeRateLinearity(model, doc.theta, rate);
  }
  return a;
}

}  // namespace turncal::report
