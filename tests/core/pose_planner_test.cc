// The table's motion (core/planning/table_motion.h), the drift-aware information of a timed pose
// sequence (core/planning/drift_design.h) and the planner that uses both
// (core/planning/pose_planner.h).
#include "core/planning/pose_planner.h"

#include <gtest/gtest.h>

#include <cmath>
#include <memory>
#include <random>

#include "core/estimation/calibrator.h"
#include "core/frames/units.h"
#include "core/planning/drift_design.h"
#include "core/planning/table_motion.h"
#include "sim/synthetic.h"

namespace turncal {
namespace {

TablePose Deg(double phi, double gamma, double psi) {
  return {phi * kRadPerDeg, gamma * kRadPerDeg, psi * kRadPerDeg};
}

TEST(TableMotion, AxisTimesFollowTheTrapezoidalProfile) {
  TableMotion m;  // 20 deg/s, 20 deg/s^2
  // Reaching 20 deg/s takes 1 s and 10 deg; stopping the same. 90 deg: 1 + 70/20 + 1 s.
  EXPECT_NEAR(m.AxisSeconds(0, 90 * kRadPerDeg), 5.5, 1e-12);
  // 20 deg exactly reaches the rate: 2 s either way.
  EXPECT_NEAR(m.AxisSeconds(0, 20 * kRadPerDeg), 2.0, 1e-12);
  // 10 deg never does: a triangle, 2 sqrt(d / a).
  EXPECT_NEAR(m.AxisSeconds(0, -10 * kRadPerDeg), 2 * std::sqrt(10.0 / 20.0), 1e-12);
  EXPECT_EQ(m.AxisSeconds(1, 0.0), 0.0);
}

TEST(TableMotion, ContinuousAxesTakeTheShorterWayAndTheSlowestAxisSetsTheTime) {
  TableMotion m;
  const Eigen::Vector3d d = m.Travel(Deg(150, -90, -170), Deg(-180, 90, 170));
  EXPECT_NEAR(d[0] * kDegPerRad, 30.0, 1e-9);   // inner: continuous, +30 not -330
  EXPECT_NEAR(d[1] * kDegPerRad, 180.0, 1e-9);  // middle: through its range
  EXPECT_NEAR(d[2] * kDegPerRad, -20.0, 1e-9);  // outer: continuous, -20 not +340
  EXPECT_NEAR(m.MoveSeconds(Deg(150, -90, -170), Deg(-180, 90, 170)), m.AxisSeconds(1, M_PI),
              1e-12);
  m.rate_dps[1] = 40.0;  // a faster middle axis: now the outer axis's 20 deg... still less
  EXPECT_NEAR(m.MoveSeconds(Deg(0, 0, 0), Deg(0, 180, 20)), m.AxisSeconds(1, M_PI), 1e-12);
  std::string error;
  m.accel_dps2[2] = 0;
  EXPECT_FALSE(m.IsValid(&error));
}

// A random 3 x N Jacobian whose last three columns are the bias (identity), as in every model.
Eigen::MatrixXd RandomJacobian(int N, std::mt19937_64* rng) {
  std::normal_distribution<double> n(0.0, 1.0);
  Eigen::MatrixXd J(3, N);
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < N; ++j) J(i, j) = n(*rng);
  J.rightCols(3).setIdentity();
  return J;
}

BiasDrift SomeDrift() {
  BiasDrift d;
  d.gm_sigma = Eigen::Vector3d(0.02, 0.01, 0.03);
  d.gm_tau_s = 100;
  d.rw_density = Eigen::Vector3d::Constant(0.0005);
  return d;
}

TEST(DriftDesign, TheInnovationAddsExactlyWhatThePoseAdds) {
  std::mt19937_64 rng(3);
  const int N = 9;
  DriftDesign design(SomeDrift(), N);
  double t = 0;
  for (int i = 0; i < 8; ++i) {
    const Eigen::MatrixXd J = RandomJacobian(N, &rng);
    const Eigen::Vector3d white(1e-4, 2e-4, 1.5e-4);
    const TimeWindow w{t + 4, t + 9};
    const Eigen::MatrixXd rows = design.InnovationRows(J, white, w);
    const Eigen::MatrixXd expected = design.Information() + rows.transpose() * rows;
    design.Add(J, white, w);
    EXPECT_LT((design.Information() - expected).norm(), 1e-8 * expected.norm()) << "pose " << i;
    t = w.t1_s;
  }
}

TEST(DriftDesign, WithoutDriftPosesAreIndependent) {
  std::mt19937_64 rng(4);
  const int N = 6;
  DriftDesign design(BiasDrift{}, N);
  Eigen::MatrixXd F = Eigen::MatrixXd::Zero(N, N);
  for (int i = 0; i < 5; ++i) {
    const Eigen::MatrixXd J = RandomJacobian(N, &rng);
    const Eigen::Vector3d white(1.0, 4.0, 9.0);
    design.Add(J, white, {10.0 * i, 10.0 * i + 5});
    F += J.transpose() * white.cwiseInverse().asDiagonal() * J;
  }
  EXPECT_LT((design.Information() - F).norm(), 1e-12 * F.norm());
  EXPECT_LT((design.InformationAtLatest() - F).norm(), 1e-12 * F.norm());
}

// With the bias free, the wander's absolute and incremental forms are one model: the other
// parameters' covariance is the same; only what the bias means differs (docs/ACCURACY.md).
TEST(DriftDesign, AbsoluteAndIncrementalFormsAgreeOnEveryParameterButTheBias) {
  std::mt19937_64 rng(5);
  const int N = 9;
  DriftDesign design(SomeDrift(), N);
  for (int i = 0; i < 12; ++i) {
    design.Add(RandomJacobian(N, &rng), Eigen::Vector3d::Constant(1e-4), {9.0 * i, 9.0 * i + 5});
  }
  const Eigen::MatrixXd ca = design.Information().inverse();
  const Eigen::MatrixXd cb = design.InformationAtLatest().inverse();
  const auto k = N - 3;
  EXPECT_LT((ca.topLeftCorner(k, k) - cb.topLeftCorner(k, k)).norm(),
            1e-6 * ca.topLeftCorner(k, k).norm());
  // The bias over the latest window is known better than the wander's mean level.
  for (int a = 0; a < 3; ++a) EXPECT_LT(cb(k + a, k + a), ca(k + a, k + a)) << "axis " << a;
}

// The planner's sigma under the drift model is the calibrator's: the records of a cube session,
// noise-free means at the truth, through the drift-aware calibrator, against the planner's
// prediction for the same poses at the same times.
TEST(DriftPlanner, PredictedSigmaIsTheCalibratorsUnderTheDriftModel) {
  SensorClass sensor = ConsumerClass();
  std::string error;
  auto model = MakeModel("accel13", ModelContext{}, &error);
  ASSERT_TRUE(model) << error;
  std::mt19937_64 rng(6);
  const Eigen::VectorXd truth = DrawTruth(*model, sensor, &rng);
  const CalibratorOptions options = DriftOptionsForClass(*model, sensor);
  const std::vector<TablePose> poses = CubePoses26();
  const double dwell_s = 5.0, white_var = 1e-6;
  const int n = 10;
  // The poses' windows when the table moves between them at its rates.
  TableMotion motion;
  std::vector<TimeWindow> windows;
  TablePose at;
  double t = 0;
  for (int i = 0; i < n; ++i) {
    t += motion.MoveSeconds(at, poses[static_cast<std::size_t>(i)]) + motion.settle_s;
    windows.push_back({t, t + dwell_s});
    t += dwell_s;
    at = poses[static_cast<std::size_t>(i)];
  }
  // A calibrator with the first k poses' records: noise-free means, white_var per axis.
  auto calibrator_with = [&](int k) {
    auto c = std::make_unique<Calibrator>(options);
    for (int i = 0; i < k; ++i) {
      PoseRecord r;
      r.pose = poses[static_cast<std::size_t>(i)];
      TriadStats s;
      s.mean = model->Predict(truth, r.pose);
      s.mean_covariance = Eigen::Matrix3d::Identity() * white_var;
      s.count = 500;
      r.acc = s;
      r.t_start_s = windows[static_cast<std::size_t>(i)].t0_s;
      r.t_end_s = windows[static_cast<std::size_t>(i)].t1_s;
      EXPECT_TRUE(c->add_pose(r, &error)) << error;
    }
    return c;
  };
  const Estimate e = calibrator_with(n)->solve();
  ASSERT_TRUE(e.ok) << e.error;
  EXPECT_NEAR(e.covariance_scale, 1.0, 1e-12);

  // The planner with the first n - 1 poses captured and the n-th as its only candidate, reached
  // in the same time.
  const auto calibrator = calibrator_with(n - 1);
  GateOptions gate;
  PlanningTarget target = TargetFromCalibrator(*calibrator, truth, dwell_s, gate);
  target.sqrt_information = Eigen::Matrix3d::Identity() / std::sqrt(white_var);
  PlannerOptions planner;
  const TablePose last = poses[static_cast<std::size_t>(n - 1)];
  planner.grid.phi = {last.phi_rad * kDegPerRad, last.phi_rad * kDegPerRad, 0};
  planner.grid.gamma = {last.gamma_rad * kDegPerRad, last.gamma_rad * kDegPerRad, 0};
  planner.grid.psi = {last.psi_rad * kDegPerRad, last.psi_rad * kDegPerRad, 0};
  planner.prior_sigma_scaled = 1e6;  // no prior to speak of, as in the calibrator
  planner.dwell_s = dwell_s;
  planner.horizon = 1;
  const NextPoseAdvice a = PlanNextPose({target}, planner);
  ASSERT_TRUE(a.ok) << a.error;
  EXPECT_TRUE(a.drift_aware);
  EXPECT_NEAR(a.seconds, windows.back().t1_s - windows[static_cast<std::size_t>(n - 2)].t1_s, 1e-9);
  const Eigen::VectorXd& predicted = a.models[0].sigma_after;
  for (int j = 0; j < model->num_parameters(); ++j) {
    EXPECT_NEAR(predicted[j] / e.sigma[j], 1.0, 0.02) << model->parameters()[j].name;
  }
}

// What the table's time buys: planning for seconds reaches the predicted gate in less table time
// than planning for poses, on the same grid and table.
TEST(DriftPlanner, PlanningForTimeNeedsLessTableTime) {
  const SensorClass sensor = IndustrialClass();
  std::string error;
  std::vector<std::unique_ptr<MeasurementModel>> models;
  std::vector<PlanningTarget> targets;
  for (const char* name : {"accel13", "mag13"}) {
    models.push_back(MakeModel(name, ModelContext{}, &error));
    ASSERT_TRUE(models.back()) << error;
    const CalibratorOptions o = DriftOptionsForClass(*models.back(), sensor);
    PlanningTarget t;
    t.model = models.back().get();
    t.theta = t.model->nominal();
    t.sqrt_information = ExpectedPoseSqrtInformation(*t.model, sensor, o, 5.0, 100.0);
    t.drift = o.drift;
    GateTolerancesForClass("industrial", &t.gate.tolerances);
    targets.push_back(t);
  }
  PlannerOptions time, poses;
  poses.objective = PlanObjective::kPoses;
  const NextPoseAdvice a = PlanNextPose(targets, time), b = PlanNextPose(targets, poses);
  ASSERT_TRUE(a.ok && b.ok) << a.error << b.error;
  ASSERT_GT(a.poses_to_gate, 0);
  ASSERT_GT(b.poses_to_gate, 0);
  EXPECT_LT(a.seconds_to_gate, b.seconds_to_gate);
  double sum = 0;
  for (double s : a.continuation_seconds) sum += s;
  EXPECT_NEAR(sum, a.seconds_to_gate, 1e-9);
  // Each step is a move from the previous pose (home first), settling and the dwell.
  TablePose at;
  for (std::size_t i = 0; i < a.continuation.size(); ++i) {
    EXPECT_NEAR(a.continuation_seconds[i],
                time.motion.MoveSeconds(at, a.continuation[i]) + time.motion.settle_s + 5.0, 1e-9);
    at = a.continuation[i];
  }
}

}  // namespace
}  // namespace turncal
