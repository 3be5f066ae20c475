#include "daemon/device_write/write_verification.h"

#include <fmt/format.h>

#include <Eigen/LU>
#include <algorithm>
#include <cmath>

#include "core/estimation/calibrator.h"
#include "core/sequencing/stillness.h"
#include "daemon/station/model_pipeline.h"
#include "drivers/mip/mip_stored.h"

namespace turncal::daemon {

double VerifyZLimit(int axes) {
  // Two-sided normal tail: erfc(z / sqrt 2) = kVerifyFalseAlarm / axes, by bisection.
  const double p = kVerifyFalseAlarm / std::max(axes, 1);
  double lo = 0.0, hi = 10.0;
  for (int i = 0; i < 100; ++i) {
    const double mid = 0.5 * (lo + hi);
    (std::erfc(mid / std::sqrt(2.0)) > p ? lo : hi) = mid;
  }
  return 0.5 * (lo + hi);
}

void OutputWindow::Add(const Sample& s) {
  const auto add = [](Sums* t, const std::optional<Eigen::Vector3d>& v) {
    if (!v) return;
    if (t->n == 0) t->first = *v;
    const Eigen::Vector3d d = *v - t->first;
    t->sum += d;
    t->sum_sq += d.cwiseProduct(d);
    t->sum_outer += d * d.transpose();
    ++t->n;
  };
  add(&acc_, s.acc_mps2);
  add(&gyr_, s.gyr_radps);
  add(&mag_, s.mag);
  ++n_;
  if (s.t_device_s) {
    t_device_sum_s_ += *s.t_device_s;
    ++n_device_time_;
  }
  t_host_sum_s_ += static_cast<double>(s.t_host_ns) * 1e-9;
}

std::optional<Eigen::Matrix3d> OutputWindow::MeanCovariance(int triad) const {
  const Sums& t = triad == kTriadAcc ? acc_ : triad == kTriadGyr ? gyr_ : mag_;
  if (t.n < 2 || t.n != n_) return std::nullopt;
  const Eigen::Vector3d mean = t.sum / t.n;
  const Eigen::Matrix3d cov = (t.sum_outer - t.n * mean * mean.transpose()) / (t.n - 1);
  return Eigen::Matrix3d(cov / t.n);
}

double OutputWindow::MeanTimeS() const {
  if (n_ == 0) return 0.0;
  return n_device_time_ == n_ ? t_device_sum_s_ / n_ : t_host_sum_s_ / n_;
}

double WanderSigma(double sigma, double tau_s, double dt_s) {
  if (!(sigma > 0) || !(tau_s > 0)) return 0.0;
  return sigma * std::sqrt(2.0 * (1.0 - std::exp(-std::abs(dt_s) / tau_s)));
}

Sample OutputWindow::Mean() const {
  Sample m;
  const auto mean = [&](const Sums& t) -> std::optional<Eigen::Vector3d> {
    if (t.n == 0 || t.n != n_) return std::nullopt;
    return t.first + t.sum / t.n;
  };
  m.acc_mps2 = mean(acc_);
  m.gyr_radps = mean(gyr_);
  m.mag = mean(mag_);
  return m;
}

std::optional<Eigen::Vector3d> OutputWindow::MeanVariance(int triad) const {
  const Sums& t = triad == kTriadAcc ? acc_ : triad == kTriadGyr ? gyr_ : mag_;
  if (t.n < 2 || t.n != n_) return std::nullopt;
  const Eigen::Vector3d mean = t.sum / t.n;
  const Eigen::Vector3d var =
      ((t.sum_sq - t.n * mean.cwiseProduct(mean)) / (t.n - 1)).cwiseMax(0.0);
  return var / t.n;
}

nlohmann::json VerifyWrite(const OutputWindow& before, const OutputWindow& after,
                           const StoredCalibration& replaced, const StoredCalibration& written,
                           const WriteAllowance& allowance) {
  Sample predicted = before.Mean();
  drivers::mip::ReexpressMipOutput(replaced, written, &predicted);
  const Sample measured = after.Mean();
  // The re-expression is affine: its linear part carries the before-mean's scatter.
  const auto linear = [&](int triad) {
    return drivers::mip::ReexpressLinear(replaced, written, triad == kTriadMag);
  };
  const Eigen::Matrix3d identity = Eigen::Matrix3d::Identity();
  const bool transform_changed =
      replaced.transform.value_or(identity) != written.transform.value_or(identity);
  const auto changed = [&](int triad) {
    if (transform_changed) return true;
    switch (triad) {
      case kTriadAcc:
        return !SameStoredVector(replaced.accel_bias, written.accel_bias);
      case kTriadGyr:
        return !SameStoredVector(replaced.gyro_bias, written.gyro_bias);
      default:
        return !SameStoredVector(replaced.hard_iron, written.hard_iron) ||
               replaced.soft_iron.has_value() != written.soft_iron.has_value() ||
               (replaced.soft_iron && *replaced.soft_iron != *written.soft_iron);
    }
  };
  nlohmann::json triads = nlohmann::json::object();
  bool pass = true;
  double worst = 0.0;
  std::string worst_at;
  std::vector<double> all_z;  // per triad compared, its largest |z|
  for (int triad : {kTriadAcc, kTriadGyr, kTriadMag}) {
    if (!changed(triad)) continue;
    const auto& m = triad == kTriadAcc   ? measured.acc_mps2
                    : triad == kTriadGyr ? measured.gyr_radps
                                         : measured.mag;
    const auto& p = triad == kTriadAcc   ? predicted.acc_mps2
                    : triad == kTriadGyr ? predicted.gyr_radps
                                         : predicted.mag;
    const auto cb = before.MeanCovariance(triad), ca = after.MeanCovariance(triad);
    const double wander = allowance.wander_sigma[triad];
    if (!m || !p || !cb || !ca) {
      pass = false;
      triads[TriadName(triad)] = {{"error", "the device's output lacks this triad"}};
      continue;
    }
    const Eigen::Matrix3d L = linear(triad);
    const Eigen::Vector3d noise_var = (L * *cb * L.transpose() + *ca).diagonal();
    const Eigen::Vector3d sigma_noise = noise_var.cwiseSqrt();
    const Eigen::Vector3d sigma =
        (noise_var + Eigen::Vector3d::Constant(wander * wander)).cwiseSqrt();
    const Eigen::Vector3d difference = *m - *p;
    Eigen::Vector3d z;
    for (int i = 0; i < 3; ++i) {
      z[i] = sigma[i] > 0 ? difference[i] / sigma[i] : (difference[i] == 0 ? 0.0 : INFINITY);
      if (std::abs(z[i]) > worst) {
        worst = std::abs(z[i]);
        worst_at = fmt::format("{} {}", TriadName(triad), "xyz"[i]);
      }
    }
    const auto vec = [](const Eigen::Vector3d& v) { return nlohmann::json{v[0], v[1], v[2]}; };
    triads[TriadName(triad)] = {{"measured", vec(*m)},
                                {"predicted", vec(*p)},
                                {"difference", vec(difference)},
                                {"sigma", vec(sigma)},
                                {"sigma_noise", vec(sigma_noise)},
                                {"sigma_wander", wander},
                                {"z", vec(z)},
                                {"unit", TriadUnit(triad)}};
    all_z.push_back(z.cwiseAbs().maxCoeff());
  }
  const int axes = 3 * static_cast<int>(all_z.size());
  const double limit = VerifyZLimit(axes);
  for (double z : all_z) pass = pass && z <= limit;
  std::string summary =
      triads.empty()
          ? "nothing to verify: the values written are those the device held, its output does not "
            "change"
          : fmt::format(
                "{}: the uncorrected output after the write {} the prediction (largest "
                "|z| {:.2f} at {}, limit {:.2f}; {} samples before, {} after)",
                pass ? "verified" : "NOT verified", pass ? "matches" : "is off", worst, worst_at,
                limit, before.count(), after.count());
  return {{"pass", pass},
          {"z_limit", limit},
          {"samples_before", before.count()},
          {"samples_after", after.count()},
          {"seconds_between", after.MeanTimeS() - before.MeanTimeS()},
          {"triads", triads},
          {"summary", summary}};
}

bool WindowMoved(const OutputWindow& window, int triad, const std::optional<Eigen::Vector3d>& sigma,
                 double factor) {
  const auto var_mean = window.MeanVariance(triad);
  if (!sigma || !var_mean) return false;
  const Eigen::Vector3d std_dev = (*var_mean * window.count()).cwiseSqrt();
  return (std_dev.array() > factor * sigma->array()).any();
}

nlohmann::json VerifyAtPose(const MeasurementModel& model, const Eigen::VectorXd& theta,
                            const Eigen::MatrixXd& covariance, const PoseRecord& record,
                            const StoredCalibration& as_if, const StoredCalibration& in_device,
                            double wander_sigma) {
  const int triad = TriadOfSensor(model.sensor());
  const TriadStats* stats = TriadFor(model.sensor(), record);
  const auto vec = [](const Eigen::Vector3d& v) { return nlohmann::json{v[0], v[1], v[2]}; };
  nlohmann::json pose = {{"phi_deg", record.pose.phi_rad * 180 / M_PI},
                         {"gamma_deg", record.pose.gamma_rad * 180 / M_PI},
                         {"psi_deg", record.pose.psi_rad * 180 / M_PI}};
  if (!stats || stats->count < 2) {
    return {{"pass", false},
            {"pose", pose},
            {"summary", "not verified: the pose's record lacks the calibrated triad"}};
  }
  // In the device's output: both re-expressed from the station's stored values into the device's.
  const auto in_device_output = [&](const Eigen::Vector3d& v) {
    Sample s;
    (triad == kTriadAcc ? s.acc_mps2 : triad == kTriadGyr ? s.gyr_radps : s.mag) = v;
    drivers::mip::ReexpressMipOutput(as_if, in_device, &s);
    return *(triad == kTriadAcc ? s.acc_mps2 : triad == kTriadGyr ? s.gyr_radps : s.mag);
  };
  const Eigen::Vector3d predicted_station = model.Predict(theta, record.pose);
  const Eigen::Vector3d measured = in_device_output(stats->mean);
  const Eigen::Vector3d predicted = in_device_output(predicted_station);
  const Eigen::Matrix3d mean_cov = SampleMeanCovariance(*stats);
  // The prediction's sigma in the device's output (through the re-expression, correlations
  // included).
  Eigen::Vector3d prediction_sigma = Eigen::Vector3d::Zero();
  if (covariance.rows() == theta.size() && covariance.cols() == theta.size()) {
    prediction_sigma = PropagatedSigma(
        [&](const Eigen::VectorXd& t) { return in_device_output(model.Predict(t, record.pose)); },
        theta, covariance);
  }
  // The re-expression's linear part.
  const Eigen::Matrix3d L = drivers::mip::ReexpressLinear(as_if, in_device, triad == kTriadMag);
  const Eigen::Vector3d noise_var = (L * mean_cov * L.transpose()).diagonal();
  const Eigen::Vector3d var = noise_var + prediction_sigma.cwiseProduct(prediction_sigma) +
                              Eigen::Vector3d::Constant(wander_sigma * wander_sigma);
  const Eigen::Vector3d sigma = var.cwiseSqrt();
  const Eigen::Vector3d difference = measured - predicted;
  Eigen::Vector3d z;
  for (int i = 0; i < 3; ++i) z[i] = sigma[i] > 0 ? difference[i] / sigma[i] : INFINITY;
  const double limit = VerifyZLimit(3);
  const bool pass = z.cwiseAbs().maxCoeff() <= limit;
  Eigen::Index worst = 0;
  z.cwiseAbs().maxCoeff(&worst);
  return {{"pass", pass},
          {"pose", pose},
          {"triads",
           {{TriadName(triad),
             {{"measured", vec(measured)},
              {"predicted", vec(predicted)},
              {"difference", vec(difference)},
              {"sigma", vec(sigma)},
              {"sigma_noise", vec(noise_var.cwiseSqrt())},
              {"sigma_calibration", vec(prediction_sigma)},
              {"sigma_wander", wander_sigma},
              {"z", vec(z)},
              {"unit", TriadUnit(triad)}}}}},
          {"summary",
           fmt::format("{} at the pose (phi {:.1f} gamma {:.1f} psi {:.1f} deg): the uncorrected "
                       "output {} the calibration's prediction (largest |z| {:.2f} at {} {}, "
                       "limit {:.2f})",
                       pass ? "verified" : "NOT verified", pose["phi_deg"].get<double>(),
                       pose["gamma_deg"].get<double>(), pose["psi_deg"].get<double>(),
                       pass ? "matches" : "is off", std::abs(z[worst]), TriadName(triad),
                       "xyz"[worst], limit)}};
}

}  // namespace turncal::daemon
