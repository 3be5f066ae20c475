// Issue 21: the gyroscope models, the rate segment's stimulus and their calibration in memory.

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>

#include "core/analysis/publish_gate.h"
#include "core/estimation/calibrator.h"
#include "core/frames/units.h"
#include "sim/synthetic.h"

namespace turncal {
namespace {

TablePose Rate(TableAxis axis, double rate_dps, double phi_deg = 0, double gamma_deg = 0,
               double psi_deg = 0) {
  TablePose p{phi_deg * kRadPerDeg, gamma_deg * kRadPerDeg, psi_deg * kRadPerDeg};
  p.rate_axis = axis;
  p.rate_radps = rate_dps * kRadPerDeg;
  return p;
}

// The rotating axis's angle of `p` set to `angle`.
TablePose At(TablePose p, double angle) {
  (p.rate_axis == TableAxis::kOuter    ? p.psi_rad
   : p.rate_axis == TableAxis::kMiddle ? p.gamma_rad
                                       : p.phi_rad) = angle;
  return p;
}

TEST(RateSegment, MeanAttitudeIsTheAverageOverARevolution) {
  for (TableAxis axis : {TableAxis::kOuter, TableAxis::kMiddle, TableAxis::kInner}) {
    const TablePose p = Rate(axis, 50, 20, -35, 70);
    Mat3<double> sum = Mat3<double>::Zero();
    const int n = 720;
    for (int k = 0; k < n; ++k) sum += At(p, 2 * M_PI * k / n).C_p_q();
    EXPECT_LT((sum / n - p.MeanC_p_q()).norm(), 1e-12) << ToString(axis);
  }
}

TEST(RateSegment, TableRateIsTheFrameRotationsRate) {
  // For frame rotations dC/dt = -[omega x] C with omega the rate of q in q.
  for (TableAxis axis : {TableAxis::kOuter, TableAxis::kMiddle, TableAxis::kInner}) {
    const TablePose p = Rate(axis, 40, 20, -35, 70);
    const double dt = 1e-6, angle = 0.3;
    const Mat3<double> C0 = At(p, angle).C_p_q();
    const Mat3<double> C1 = At(p, angle + p.rate_radps * dt).C_p_q();
    const Mat3<double> W = -(C1 - C0) / dt * C0.transpose();
    const Eigen::Vector3d omega(W(2, 1), W(0, 2), W(1, 0));
    EXPECT_LT((omega - p.TableRate_q()).norm(), 1e-6 * p.rate_radps) << ToString(axis);
  }
  EXPECT_EQ(TablePose{}.TableRate_q(), Eigen::Vector3d::Zero());
}

TEST(RateSegment, EarthRateAtTheLatitude) {
  ReferenceVectors ref;
  ref.latitude_deg = 60;
  const Eigen::Vector3d w = EarthRateNed(ref);
  EXPECT_NEAR(w.norm(), 7.292115e-5, 1e-12);
  EXPECT_NEAR(w.x(), 7.292115e-5 * 0.5, 1e-12);
  EXPECT_LT(w.z(), 0.0);  // up: NED's down axis is negative
  ref.latitude_deg = 91;
  std::string error;
  EXPECT_FALSE(ref.IsValid(&error));
  EXPECT_NE(error.find("latitude"), std::string::npos);
}

TEST(GyroModels, NominalPredictionIsTheInertialRate) {
  std::string error;
  for (const char* name : {"gyro12", "gyro21"}) {
    auto m = MakeModel(name, ModelContext{}, &error);
    ASSERT_NE(m, nullptr) << error;
    EXPECT_EQ(m->sensor(), SensorKind::kGyroscope);
    const TablePose still{0.2, -0.4, 1.0};
    EXPECT_LT((m->Predict(m->nominal(), still) - still.C_p_q() * EarthRateNed({})).norm(), 1e-15);
    const TablePose spin = Rate(TableAxis::kInner, 100, 0, 30, 0);
    const Eigen::Vector3d expected =
        spin.MeanC_p_q() * EarthRateNed({}) + Eigen::Vector3d(100 * kRadPerDeg, 0, 0);
    EXPECT_LT((m->Predict(m->nominal(), spin) - expected).norm(), 1e-15);
  }
}

TEST(GyroModels, GSensitivityAndCorrectionInvertThePrediction) {
  std::string error;
  auto m = MakeModel("gyro21", ModelContext{}, &error);
  std::mt19937_64 rng(3);
  const Eigen::VectorXd truth = DrawTruth(*m, ConsumerClass(), &rng);
  const TablePose spin = Rate(TableAxis::kOuter, -60, 30, 10, 0);
  const Eigen::Vector3d omega_q = spin.MeanC_p_q() * EarthRateNed({}) + spin.TableRate_q();
  const Eigen::Vector3d f_q = spin.MeanC_p_q() * SpecificForceNed({});
  const Eigen::Vector3d raw = m->Predict(truth, spin);
  // In the table frame the correction returns the inertial rate itself.
  ModelContext table;
  table.accel_output_frame = OutputFrame::kTable;
  auto mt = MakeModel("gyro21", table, &error);
  EXPECT_LT((mt->CorrectWithForce(truth, raw, f_q) - omega_q).norm(), 1e-12);
  // Without the force, the g-sensitivity's term is left in.
  EXPECT_GT((mt->Correct(truth, raw) - omega_q).norm(), 1e-6);
}

TEST(GyroModels, StructurallyObservableAndRateRecordsOnlyForGyros) {
  std::string error;
  for (const char* name : {"gyro12", "gyro21"}) {
    auto m = MakeModel(name, ModelContext{}, &error);
    Eigen::MatrixXd J;
    m->Extended(m->nominal(), &J);
    Eigen::FullPivLU<Eigen::MatrixXd> lu(J);
    EXPECT_EQ(lu.rank(), m->num_parameters()) << name;
  }
  Calibrator accel(
      OptionsForClass(*MakeModel("accel13", ModelContext{}, &error), IndustrialClass()));
  PoseRecord r;
  r.pose = Rate(TableAxis::kInner, 10);
  r.acc = TriadStats{};
  r.acc->count = 10;
  r.acc->covariance = Eigen::Matrix3d::Identity();
  EXPECT_FALSE(accel.add_pose(r, &error));
  EXPECT_NE(error.find("rate segment"), std::string::npos) << error;
}

// Static poses (the 26 cube directions) and rate segments: +-R about each axis at attitudes that
// turn the rate through q's three axes, each lasting two revolutions.
std::vector<std::pair<TablePose, double>> MixedSession(bool with_rates, bool with_static) {
  std::vector<std::pair<TablePose, double>> out;
  if (with_static) {
    for (const auto& p : CubePoses26()) out.push_back({p, 5.0});
  }
  if (with_rates) {
    for (double r : {100.0, -100.0, 30.0, -30.0}) {
      const double T = 2 * 360 / std::abs(r);
      out.push_back({Rate(TableAxis::kInner, r, 0, 0, 0), T});
      out.push_back({Rate(TableAxis::kMiddle, r, 0, 0, 0), T});
      out.push_back({Rate(TableAxis::kMiddle, r, 90, 0, 0), T});
      out.push_back({Rate(TableAxis::kOuter, r, 0, 0, 0), T});
      out.push_back({Rate(TableAxis::kOuter, r, 90, 0, 0), T});
      out.push_back({Rate(TableAxis::kOuter, r, 0, 90, 0), T});
    }
  }
  return out;
}

struct ZStats {
  Eigen::VectorXd sum, sum2;
  int n = 0;
};

ZStats MonteCarlo(const std::string& name, const SensorClass& sensor, int runs,
                  bool with_rates = true, bool with_static = true) {
  std::string error;
  auto model = MakeModel(name, ModelContext{}, &error);
  ZStats z;
  z.sum = z.sum2 = Eigen::VectorXd::Zero(model->num_parameters());
  for (int run = 0; run < runs; ++run) {
    std::mt19937_64 rng(1000 + static_cast<std::uint64_t>(run));
    const Eigen::VectorXd truth = DrawTruth(*model, sensor, &rng);
    Calibrator calibrator(OptionsForClass(*model, sensor));
    for (const auto& [pose, T] : MixedSession(with_rates, with_static)) {
      EXPECT_TRUE(calibrator.add_pose(SimulateRecord(*model, truth, pose, sensor, T, &rng), &error))
          << error;
    }
    const Estimate e = calibrator.solve();
    EXPECT_TRUE(e.ok) << e.error;
    if (!e.ok) continue;
    const Eigen::VectorXd zi = (e.theta - truth).cwiseQuotient(e.sigma);
    z.sum += zi;
    z.sum2 += zi.cwiseAbs2();
    ++z.n;
  }
  return z;
}

// 200 runs: the mean z has sigma 1/sqrt(200) = 0.071 (|mean| < 0.3 is 4.2 sigma), the std z
// sigma ~ 1/sqrt(400) = 0.05 (0.8-1.2 is 4 sigma).
void ExpectHonest(const std::string& name, const SensorClass& sensor) {
  const ZStats z = MonteCarlo(name, sensor, 200);
  ASSERT_EQ(z.n, 200);
  std::string error;
  auto model = MakeModel(name, ModelContext{}, &error);
  for (int i = 0; i < model->num_parameters(); ++i) {
    const double mean = z.sum[i] / z.n;
    const double sd = std::sqrt(z.sum2[i] / z.n - mean * mean);
    if (std::getenv("TURNCAL_PRINT_Z")) {
      std::printf("%s %s %-6s mean z %+.3f std z %.3f\n", name.c_str(), sensor.name.c_str(),
                  model->parameters()[i].name.c_str(), mean, sd);
    }
    EXPECT_LT(std::abs(mean), 0.3)
        << name << " " << sensor.name << " " << model->parameters()[i].name;
    EXPECT_GT(sd, 0.8) << name << " " << sensor.name << " " << model->parameters()[i].name;
    EXPECT_LT(sd, 1.2) << name << " " << sensor.name << " " << model->parameters()[i].name;
  }
}

TEST(GyroCalibration, Gyro12IsHonestIndustrial) { ExpectHonest("gyro12", IndustrialClass()); }
TEST(GyroCalibration, Gyro21IsHonestIndustrial) { ExpectHonest("gyro21", IndustrialClass()); }
TEST(GyroCalibration, Gyro12IsHonestConsumer) { ExpectHonest("gyro12", ConsumerClass()); }
TEST(GyroCalibration, Gyro21IsHonestConsumer) { ExpectHonest("gyro21", ConsumerClass()); }

TEST(GyroCalibration, RateSegmentsDetermineScaleStaticPosesDoNot) {
  std::string error;
  const SensorClass sensor = IndustrialClass();
  auto model = MakeModel("gyro12", ModelContext{}, &error);
  std::mt19937_64 rng(5);
  const Eigen::VectorXd truth = DrawTruth(*model, sensor, &rng);
  auto solve = [&](bool with_rates) {
    Calibrator calibrator(OptionsForClass(*model, sensor));
    for (const auto& [pose, T] : MixedSession(with_rates, true)) {
      EXPECT_TRUE(
          calibrator.add_pose(SimulateRecord(*model, truth, pose, sensor, T, &rng), &error));
    }
    return calibrator.solve();
  };
  const Estimate mixed = solve(true);
  ASSERT_TRUE(mixed.ok) << mixed.error;
  GateOptions gate;
  ASSERT_TRUE(GateDefaultsForClass("industrial", &gate));
  // With rate segments, the gated parameters reach the industrial tolerances.
  EXPECT_TRUE(PrecisionShortfalls(*model, mixed.sigma, gate).empty())
      << PrecisionShortfalls(*model, mixed.sigma, gate).front();
  // Static poses see only the Earth's rate (7.3e-5 rad/s against 5.5e-5 rad/s of noise per pose):
  // the scale factors are undetermined at the tolerance.
  const Estimate still = solve(false);
  ASSERT_TRUE(still.ok) << still.error;
  EXPECT_GT(still.sigma[model->index_of("Sx")], 0.05);
  EXPECT_LT(still.sigma[model->index_of("bx")], 10 * kRadPerDeg / 3600);
}

TEST(GyroCalibration, StaticPosesFirstThenRatesEndOnTheTruthsBranch) {
  // Solved after every record: the static poses alone leave G to the Earth's rate, and a solve
  // there may end on an equivalent branch (eps_x + pi with 1 + Sy, 1 + Sz negated); the estimate
  // is reported on the LQ decomposition's branch, so the rate segments' solves start there and
  // end at the truth.
  std::string error;
  const SensorClass sensor = IndustrialClass();
  auto model = MakeModel("gyro12", ModelContext{}, &error);
  for (std::uint64_t seed : {7, 8, 9}) {
    std::mt19937_64 rng(seed);
    const Eigen::VectorXd truth = DrawTruth(*model, sensor, &rng);
    Calibrator calibrator(OptionsForClass(*model, sensor));
    std::vector<std::pair<TablePose, double>> records = MixedSession(false, true);
    for (const auto& r : MixedSession(true, false)) records.push_back(r);
    Estimate e;
    for (const auto& [pose, T] : records) {
      ASSERT_TRUE(
          calibrator.add_pose(SimulateRecord(*model, truth, pose, sensor, T, &rng), &error));
      if (calibrator.num_poses() >= 6) e = calibrator.solve();
      if (e.ok) {
        for (int i = 0; i < 3; ++i) EXPECT_GT(1 + e.theta[i], 0) << "1 + S must stay positive";
      }
    }
    ASSERT_TRUE(e.ok) << e.error;
    for (int i = 0; i < e.theta.size(); ++i) {
      EXPECT_LT(std::abs(e.theta[i] - truth[i]) / e.sigma[i], 4.0)
          << "seed " << seed << " " << e.parameters[i].name;
    }
  }
}

}  // namespace
}  // namespace turncal
