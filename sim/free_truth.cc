#include "sim/free_truth.h"

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>
#include <Eigen/LU>
#include <algorithm>

#include "core/models/accel_common.h"

namespace turncal::sim {
namespace {

Eigen::Matrix3d InverseSqrt(const Eigen::Matrix3d& A) {
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(A);
  return eig.eigenvectors() * eig.eigenvalues().cwiseInverse().cwiseSqrt().asDiagonal() *
         eig.eigenvectors().transpose();
}

Eigen::Vector3d MeanWander(const SimulatedSession& s, int triad,
                           const std::optional<TimeWindow>& window) {
  if (window) {
    return triad == 0   ? s.AccDriftMean(window->t0_s, window->t1_s)
           : triad == 1 ? s.MagDriftMean(window->t0_s, window->t1_s)
                        : s.GyrDriftMean(window->t0_s, window->t1_s);
  }
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  for (const auto& e : s.events) {
    sum += triad == 0 ? e.acc_wander_mean : triad == 1 ? e.mag_wander_mean : e.gyr_wander_mean;
  }
  return s.events.empty() ? sum : Eigen::Vector3d(sum / static_cast<double>(s.events.size()));
}

}  // namespace

bool FreeTruth(const SimCapture& capture, const std::string& free_model, const FreeContext& context,
               const std::optional<TimeWindow>& bias_window, Eigen::VectorXd* truth,
               std::string* error) {
  auto fail = [&](const std::string& why) {
    if (error) *error = why;
    return false;
  };
  const SimulatedSession& s = capture.session;
  ModelContext mc;
  std::string e;
  auto accel = MakeModel(capture.accel_model, mc, &e);
  if (!accel || (capture.accel_model != "accel12" && capture.accel_model != "accel13")) {
    return fail("the free truths need an accel12 or accel13 truth");
  }
  // accel9.
  const Eigen::Matrix3d Ga = accel::G(s.accel_truth.data(), mc.mounting);
  const Eigen::Matrix3d A = (Ga * Ga.transpose()).inverse();
  const Eigen::Matrix3d C = Eigen::LLT<Eigen::Matrix3d>(A).matrixL().transpose();
  const Eigen::Matrix3d Qa = C * Ga;
  Eigen::VectorXd a9(9);
  for (int i = 0; i < 3; ++i) a9[i] = C(i, i);
  a9[3] = -C(0, 1) / C(1, 1);
  a9[4] = C(0, 2) / C(2, 2);
  a9[5] = -C(1, 2) / C(2, 2);
  a9.tail<3>() = s.accel_truth.tail<3>() + MeanWander(s, 0, bias_window);
  if (free_model == "accel9") {
    *truth = a9;
    return true;
  }
  if (free_model == "gyro9" || free_model == "gyro9g") {
    if (capture.gyro_model.empty() || s.gyro_truth.size() == 0) {
      return fail("a gyro free model needs a session with a gyro model (gyro12, gyro21)");
    }
    auto gyro = MakeModel(capture.gyro_model, mc, &e);
    if (!gyro) return fail(e);
    const Eigen::VectorXd& t = s.gyro_truth;
    const Eigen::Vector3d b =
        gyro->PredictRate(t, Eigen::Vector3d::Zero(), Eigen::Vector3d::Zero());
    Eigen::Matrix3d Gw, B;
    for (int i = 0; i < 3; ++i) {
      Gw.col(i) = gyro->PredictRate(t, Eigen::Vector3d::Unit(i), Eigen::Vector3d::Zero()) - b;
      B.col(i) = gyro->PredictRate(t, Eigen::Vector3d::Zero(), Eigen::Vector3d::Unit(i)) - b;
    }
    const Eigen::Matrix3d M = Qa * Gw.inverse();
    const bool with_g = free_model == "gyro9g";
    Eigen::VectorXd g(with_g ? 21 : 12);
    for (int i = 0; i < 3; ++i) g[i] = M(i, i);
    Eigen::Matrix3d T = M;
    for (int c = 0; c < 3; ++c) T.col(c) /= M(c, c);
    g[3] = -T(0, 1);
    g[4] = T(0, 2);
    g[5] = -T(1, 2);
    g[6] = T(1, 0);
    g[7] = -T(2, 0);
    g[8] = T(2, 1);
    g.segment<3>(9) = b + MeanWander(s, 2, bias_window);
    if (with_g) {
      const Eigen::Matrix3d Bf = B * Qa.transpose();
      for (int i = 0; i < 9; ++i) g[12 + i] = Bf(i / 3, i % 3);
    }
    *truth = g;
    return true;
  }
  if (capture.mag_model != "mag13") return fail("the magnetometer's free truths need mag13");
  Eigen::Matrix3d Gm;
  for (int i = 0; i < 9; ++i) Gm(i / 3, i % 3) = s.mag_truth[i];
  const double field = mc.reference.B_ned.norm();
  const double F = context.field_magnitude > 0 ? context.field_magnitude : 1.0;
  const Eigen::Matrix3d S = (F / field) * InverseSqrt(Gm * Gm.transpose());
  Eigen::VectorXd m9(9);
  m9.head<3>() = s.mag_truth.tail<3>() + MeanWander(s, 1, bias_window);
  m9.tail<6>() << S(0, 0), S(0, 1), S(0, 2), S(1, 1), S(1, 2), S(2, 2);
  if (free_model == "magellipsoid") {
    *truth = m9;
    return true;
  }
  if (free_model == "accmag") {
    const Eigen::Matrix3d U = S * Gm * (field / F);
    const Eigen::AngleAxisd R(Eigen::Matrix3d(Qa * U.transpose()));
    // The dip as the simulated sensors see it: the specific force and the field in the table's
    // frame at a pose, from the models' own predictions (each model turns its reference vector by
    // its own heading beta, so the angle between them is not quite the reference's).
    auto mag = MakeModel(capture.mag_model, mc, &e);
    if (!mag) return fail(e);
    const TablePose level;
    const Eigen::Vector3d f_q =
        Ga.inverse() * (accel->Predict(s.accel_truth, level) - s.accel_truth.tail<3>());
    const Eigen::Vector3d h_q =
        Gm.inverse() * (mag->Predict(s.mag_truth, level) - s.mag_truth.tail<3>());
    Eigen::VectorXd j(22);
    j << a9, m9, R.angle() * R.axis(),
        std::asin(std::clamp(-f_q.normalized().dot(h_q.normalized()), -1.0, 1.0));
    *truth = j;
    return true;
  }
  return fail("no simulated truth for the free model '" + free_model + "'");
}

}  // namespace turncal::sim
