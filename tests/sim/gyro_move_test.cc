// Issue 21, the third source: the moves between static poses as the gyro saw them
// (core/estimation/move_residual.h) -- zero at the truth, its analytic Jacobian, and gyro12
// calibrated from static poses and moves alone (no rate segment), honestly.

#include <gtest/gtest.h>

#include <cmath>

#include "core/estimation/calibrator.h"
#include "core/estimation/move_residual.h"
#include "sim/session_sim.h"

namespace turncal {
namespace {

struct MoveRun {
  std::unique_ptr<MeasurementModel> accel, mag, gyro;
  SimulatedSession session;
  SessionSimOptions options;
};

MoveRun Simulate(const std::string& model, const SensorClass& sensor, std::uint64_t seed,
                 bool noiseless = false, int poses = 36, double rate_hz = 0) {
  MoveRun r;
  std::string error;
  r.accel = MakeModel("accel13", ModelContext{}, &error);
  r.mag = MakeModel("mag13", ModelContext{}, &error);
  r.gyro = MakeModel(model, ModelContext{}, &error);
  r.options.sensor = sensor;
  r.options.rate_hz = rate_hz > 0 ? rate_hz : sensor.rate_hz;
  r.options.seed = seed;
  if (noiseless) {
    r.options.sensor.gyr_noise_density = 0;
    r.options.sensor.gyr_bias_instability = 0;
    r.options.sensor.gyr_quantum = 0;
  }
  std::vector<TablePose> plan = DefaultSessionPoses();
  plan.resize(static_cast<std::size_t>(poses));
  r.session = SimulateSession(*r.accel, *r.mag, plan, r.options, r.gyro.get());
  return r;
}

TEST(GyroMove, TheResidualIsZeroAtTheTruthAndItsJacobianIsRight) {
  // The turn is the table's to within 2e-6 rad at 100 Hz and 4e-7 at 500 Hz. Measured with the
  // second-order term (core/estimation/move_integrator.h): 6e-7 to 9e-7 and 2e-8 to 2e-7; the
  // trapezoid alone left up to 7e-5 at 100 Hz. Against a move's angle random walk for the
  // industrial class (2.8e-4 rad over 5 s): below 0.01 sigma.
  for (const double rate_hz : {100.0, 500.0}) {
    const MoveRun r = Simulate("gyro12", IndustrialClass(), 4, /*noiseless=*/true, 8, rate_hz);
    const double limit = rate_hz < 200 ? 2e-6 : 4e-7;
    std::string error;
    for (std::size_t i = 0; i + 1 < r.session.events.size(); ++i) {
      const MoveRecord m =
          MoveBetween(r.session, r.session.events[i], r.session.events[i + 1], r.options.rate_hz);
      auto residual = MoveResidual::Make(*r.gyro, m, r.session.gyro_truth, 1e-4, &error);
      ASSERT_NE(residual, nullptr) << error;
      EXPECT_LT(residual->RotationError(r.session.gyro_truth).norm(), limit)
          << "move " << i << " at " << rate_hz << " Hz";
      if (rate_hz < 200) continue;
      // Analytic against central differences, away from the truth.
      Eigen::VectorXd theta = r.session.gyro_truth;
      theta[0] += 1e-3;
      theta[r.gyro->index_of("eps_z")] += 2e-3;
      const int N = r.gyro->num_parameters();
      Eigen::Matrix<double, 3, Eigen::Dynamic, Eigen::RowMajor> J(3, N);
      Eigen::Vector3d value;
      const double* parameters[] = {theta.data()};
      double* jacobians[] = {J.data()};
      ASSERT_TRUE(residual->Evaluate(parameters, value.data(), jacobians));
      for (int k = 0; k < N; ++k) {
        const double h = 1e-7;
        Eigen::VectorXd up = theta, down = theta;
        up[k] += h;
        down[k] -= h;
        Eigen::Vector3d vu, vd;
        const double* pu[] = {up.data()};
        const double* pd[] = {down.data()};
        residual->Evaluate(pu, vu.data(), nullptr);
        residual->Evaluate(pd, vd.data(), nullptr);
        const Eigen::Vector3d numeric = (vu - vd) / (2 * h);
        // Within 0.5 % of the column: second order in each block's turn (< 0.03 rad); what is
        // left is Log's own Jacobian at r, ~3e-3 rad away from the truth (measured 0.4 %; the
        // first-order Jacobian, without SO(3)'s left Jacobian, was within 2 %).
        EXPECT_LT((J.col(k) - numeric).norm(), 0.005 * numeric.norm() + 1e-9)
            << "move " << i << " " << r.gyro->parameters()[static_cast<std::size_t>(k)].name;
      }
    }
  }
}

// Static poses and the moves between them; no rate segment.
Estimate CalibrateFromMoves(const MoveRun& r, bool with_moves) {
  std::string error;
  Calibrator calibrator(DriftOptionsForClass(*r.gyro, r.options.sensor));
  const auto& events = r.session.events;
  for (std::size_t i = 0; i < events.size(); ++i) {
    EXPECT_TRUE(
        calibrator.add_pose(DwellRecord(r.session, events[i], SensorKind::kGyroscope), &error))
        << error;
    if (with_moves && i + 1 < events.size()) {
      EXPECT_TRUE(calibrator.add_move(
          MoveBetween(r.session, events[i], events[i + 1], r.options.rate_hz), &error))
          << error;
    }
  }
  return calibrator.solve();
}

Eigen::VectorXd Truth(const MoveRun& r) {
  Eigen::VectorXd truth = r.session.gyro_truth;
  truth.segment<3>(r.gyro->index_of("bx")) += r.session.events.back().gyr_wander_mean;
  return truth;
}

TEST(GyroMove, MovesAloneCalibrateGyro12WithinFourSigma) {
  for (std::uint64_t seed : {1, 2}) {
    const MoveRun r = Simulate("gyro12", IndustrialClass(), seed);
    const Estimate e = CalibrateFromMoves(r, true);
    ASSERT_TRUE(e.ok) << e.error;
    const Eigen::VectorXd truth = Truth(r);
    for (int i = 0; i < e.theta.size(); ++i) {
      EXPECT_LT(std::abs(e.theta[i] - truth[i]) / e.sigma[i], 4.0)
          << "seed " << seed << " " << e.parameters[i].name << " est " << e.theta[i] << " truth "
          << truth[i] << " sigma " << e.sigma[i];
    }
    // Without the moves the static poses see only the Earth's rate: the scale factors are
    // thousands of times less certain.
    const Estimate still = CalibrateFromMoves(r, false);
    ASSERT_TRUE(still.ok) << still.error;
    EXPECT_GT(still.sigma[0], 100 * e.sigma[0]);
  }
}

void ExpectHonestOverManySessions(double rate_hz) {
  // 40 sessions: std z within [0.7, 1.3] (4 sigma of the spread of 40 draws, ~0.11) and |mean|
  // below 0.65 (4 / sqrt(40)). At 100 Hz Sz's mean z was -0.87 with the trapezoid alone, -0.48
  // with dt^2 / 12 (core/estimation/move_integrator.h); now within +-0.1 at both rates.
  std::string error;
  auto model = MakeModel("gyro12", ModelContext{}, &error);
  const int N = model->num_parameters(), runs = 40;
  Eigen::VectorXd sum = Eigen::VectorXd::Zero(N), sum2 = Eigen::VectorXd::Zero(N);
  for (int run = 0; run < runs; ++run) {
    const MoveRun r = Simulate("gyro12", IndustrialClass(), 100 + static_cast<std::uint64_t>(run),
                               false, 20, rate_hz);
    const Estimate e = CalibrateFromMoves(r, true);
    ASSERT_TRUE(e.ok) << e.error;
    const Eigen::VectorXd z = (e.theta - Truth(r)).cwiseQuotient(e.sigma);
    sum += z;
    sum2 += z.cwiseAbs2();
  }
  for (int i = 0; i < N; ++i) {
    const double mean = sum[i] / runs, sd = std::sqrt(sum2[i] / runs - mean * mean);
    if (std::getenv("TURNCAL_PRINT_Z")) {
      std::printf("%-6s mean z %+.3f std z %.3f\n",
                  model->parameters()[static_cast<std::size_t>(i)].name.c_str(), mean, sd);
    }
    EXPECT_LT(std::abs(mean), 0.65) << model->parameters()[static_cast<std::size_t>(i)].name;
    EXPECT_GT(sd, 0.7) << model->parameters()[static_cast<std::size_t>(i)].name;
    EXPECT_LT(sd, 1.3) << model->parameters()[static_cast<std::size_t>(i)].name;
  }
}

TEST(GyroMove, MovesAreHonestOverManySessionsAt500Hz) { ExpectHonestOverManySessions(500); }
TEST(GyroMove, MovesAreHonestOverManySessionsAt100Hz) { ExpectHonestOverManySessions(100); }

}  // namespace
}  // namespace turncal
