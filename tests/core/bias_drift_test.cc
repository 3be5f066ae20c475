// The drift kernel (core/estimation/bias_drift.h), the GLS whitening
// (core/estimation/gls_whitening.h) and the drift-aware calibrator against sessions whose bias
// wanders in time.
#include "core/estimation/bias_drift.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "core/estimation/calibrator.h"
#include "core/estimation/gls_whitening.h"
#include "sim/session_sim.h"
#include "sim/synthetic.h"

namespace turncal {
namespace {

// The double integral of k(t - s) over two windows by the midpoint rule (fine grid).
template <typename K>
double Quadrature(const TimeWindow& a, const TimeWindow& b, K k) {
  const int n = 2000;
  const double ha = a.duration_s() / n, hb = b.duration_s() / n;
  double sum = 0;
  for (int i = 0; i < n; ++i)
    for (int j = 0; j < n; ++j) sum += k(a.t0_s + (i + 0.5) * ha, b.t0_s + (j + 0.5) * hb);
  return sum / (n * n);
}

TEST(BiasDrift, GaussMarkovWindowCovarianceIsTheAveragedKernel) {
  BiasDrift d;
  d.gm_sigma = Eigen::Vector3d(2.0, 0.0, 0.0);
  d.gm_tau_s = 30.0;
  const auto k = [&](double t, double s) { return 4.0 * std::exp(-std::abs(t - s) / 30.0); };
  const TimeWindow cases[][2] = {{{0, 5}, {0, 5}},        // the same window
                                 {{0, 5}, {9, 14}},       // disjoint
                                 {{0, 5}, {3, 10}},       // overlapping
                                 {{100, 101}, {0, 50}}};  // the second before the first
  for (const auto& c : cases) {
    const double exact = d.WindowCovariance(0, c[0], c[1], 0.0);
    EXPECT_NEAR(exact, Quadrature(c[0], c[1], k), 1e-5 * std::abs(exact));
    EXPECT_EQ(d.WindowCovariance(1, c[0], c[1], 0.0), 0.0);  // that axis has no drift
  }
  // Windows much shorter than tau: the point kernel.
  EXPECT_NEAR(d.WindowCovariance(0, {0, 1e-3}, {60, 60.001}, 0.0), 4.0 * std::exp(-2.0), 1e-5);
}

TEST(BiasDrift, RandomWalkIncrementsDoNotDependOnTheOrigin) {
  BiasDrift d;
  d.rw_density = Eigen::Vector3d::Constant(0.1);
  const std::vector<TimeWindow> w = {{0, 5}, {9, 14}, {18, 23}};
  const Eigen::MatrixXd D = DriftIncrementCovariance(d, 2, w, 2);
  // Var(ubar_0 - ubar_2) for a Wiener process: q^2 (distance between the windows' starts
  // 18 - 0 - (5 - 5/3) - ... computed by quadrature of min(t, s).
  const auto k = [](double t, double s) { return 0.01 * std::min(t, s); };
  const double v00 = Quadrature(w[0], w[0], k), v22 = Quadrature(w[2], w[2], k),
               v02 = Quadrature(w[0], w[2], k);
  EXPECT_NEAR(D(0, 0), v00 + v22 - 2 * v02, 1e-6);
  EXPECT_EQ(D(2, 2), 0.0);
  EXPECT_EQ(D(0, 2), 0.0);
  // The same with every time shifted by 1000 s.
  std::vector<TimeWindow> shifted;
  for (auto x : w) shifted.push_back({x.t0_s + 1000, x.t1_s + 1000});
  EXPECT_NEAR((DriftIncrementCovariance(d, 2, shifted, 2) - D).norm(), 0.0, 1e-9);
  // After a window of T, a random walk has moved q^2 (dt + T/3) from the window's mean.
  EXPECT_NEAR(d.VarianceSince(0, {0, 6}, 6 + 100), 0.01 * (100 + 2), 1e-9);
  // Inside the window, at its middle: Var(u(3) - ubar) over [0, 6] is q^2 T / 12 = 0.005.
  EXPECT_NEAR(d.VarianceSince(0, {0, 6}, 3), 0.01 * 6 / 12, 1e-9);
}

// What a still dwell's halves may differ by through the wander: for a Wiener process the two
// halves' means straddle u(T1), each at q^2 T / 3 from it, so q^2 (T1 + T2) / 3 exactly; for a
// Gauss-Markov process the kernel's double integrals; a warm-up is not counted.
TEST(BiasDrift, HalvesDifferenceVarianceIsTheWandersBetweenAdjacentWindows) {
  BiasDrift rw;
  rw.rw_density = Eigen::Vector3d::Constant(0.1);
  EXPECT_NEAR(rw.HalvesDifferenceVariance(1, 1.5, 2.5), 0.01 * (1.5 + 2.5) / 3, 1e-12);
  BiasDrift gm;
  gm.gm_sigma = Eigen::Vector3d(0.06, 0.0, 0.0);
  gm.gm_tau_s = 100.0;
  gm.warmup_sigma = Eigen::Vector3d::Constant(1.0);  // left out
  const auto k = [](double t, double s) { return 0.0036 * std::exp(-std::abs(t - s) / 100.0); };
  const TimeWindow a{0, 1.5}, b{1.5, 3.0};
  const double quadrature = Quadrature(a, a, k) + Quadrature(b, b, k) - 2 * Quadrature(a, b, k);
  EXPECT_NEAR(gm.HalvesDifferenceVariance(0, 1.5, 1.5), quadrature, 1e-3 * quadrature);
  // Short against tau, the Gauss-Markov process is a random walk of q^2 = 2 sigma^2 / tau.
  EXPECT_NEAR(gm.HalvesDifferenceVariance(0, 1.5, 1.5), 2 * 0.0036 / 100 * 3.0 / 3, 0.02 * 7.2e-5);
  EXPECT_EQ(gm.HalvesDifferenceVariance(1, 1.5, 1.5), 0.0);
  EXPECT_EQ(gm.HalvesDifferenceVariance(0, 0.0, 1.5), 0.0);
}

TEST(BiasDrift, SigmaGrowsWithTimeSinceTheCalibrationToTheStationaryLimit) {
  BiasDrift d;
  d.gm_sigma = Eigen::Vector3d::Constant(1.0);
  d.gm_tau_s = 100;
  const TimeWindow ref{0, 5};
  double last = 0;
  for (double dt : {0.0, 10.0, 100.0, 5000.0}) {
    const double s = d.SigmaAfter(ref, dt)[0];
    EXPECT_GT(s, last);
    last = s;
  }
  // Long after: the bias then and the window's mean are nearly independent: 2 sigma^2 less
  // what the window's averaging removed.
  EXPECT_NEAR(last * last, 1.0 + d.WindowCovariance(0, ref, ref, 0), 1e-6);
  EXPECT_FALSE(BiasDrift{Eigen::Vector3d(-1, 0, 0)}.IsValid(nullptr));
}

TEST(GlsWhitening, InnovationsSquaredSumToTheMahalanobisNorm) {
  BiasDrift d;
  d.gm_sigma = Eigen::Vector3d(1e-3, 2e-3, 3e-3);
  d.gm_tau_s = 50;
  std::vector<TimeWindow> w;
  std::vector<Eigen::Matrix3d> white;
  for (int i = 0; i < 8; ++i) {
    // Out of time order on purpose: the whitening sorts.
    const double t0 = 9.0 * ((i * 5) % 8);
    w.push_back({t0, t0 + 5});
    white.push_back(Eigen::Matrix3d::Identity() * 1e-8 * (1 + i));
  }
  GlsWhitening g;
  std::string error;
  ASSERT_TRUE(BuildGlsWhitening(w, white, d, &g, &error)) << error;
  EXPECT_EQ(w[static_cast<std::size_t>(g.order.back())].t0_s, 63.0);
  std::mt19937_64 rng(3);
  std::normal_distribution<double> normal;
  Eigen::VectorXd r(24);
  for (int i = 0; i < 24; ++i) r[i] = 1e-3 * normal(rng);
  EXPECT_NEAR((g.W * r).squaredNorm(), r.dot(g.C.ldlt().solve(r)), 1e-9 * (g.W * r).squaredNorm());
  EXPECT_TRUE(g.W.isLowerTriangular(1e-12));
}

struct DriftZ {
  Eigen::VectorXd mean, std;
};

// Sessions of the sample-level simulator (Gauss-Markov wander, tau 100 s, against ~9 s per pose)
// over the ordered cube plan, calibrated with `options_for`; z of every parameter against the
// truth the options define (the bias over the last pose with drift, the dwells' mean without).
template <typename OptionsFor>
DriftZ ZOverSessions(const std::string& model_name, const SensorClass& sensor, int runs,
                     OptionsFor options_for, bool drift) {
  std::string error;
  auto model = MakeModel(model_name, ModelContext{}, &error);
  auto other = MakeModel(model->sensor() == SensorKind::kAccelerometer ? "mag13" : "accel13",
                         ModelContext{}, &error);
  const bool accel = model->sensor() == SensorKind::kAccelerometer;
  const auto poses = DefaultSessionPoses();
  const int N = model->num_parameters();
  Eigen::VectorXd s1 = Eigen::VectorXd::Zero(N), s2 = Eigen::VectorXd::Zero(N);
  for (int run = 0; run < runs; ++run) {
    SessionSimOptions o;
    o.sensor = sensor;
    o.rate_hz = 50;
    o.seed = 1000 + static_cast<std::uint64_t>(run);
    const SimulatedSession s = accel ? SimulateSession(*model, *other, poses, o)
                                     : SimulateSession(*other, *model, poses, o);
    Calibrator c(options_for(*model, sensor));
    for (const auto& e : s.events)
      EXPECT_TRUE(c.add_pose(DwellRecord(s, e, model->sensor()), &error));
    const Estimate est = c.solve();
    EXPECT_TRUE(est.ok) << est.error;
    Eigen::VectorXd truth = accel ? s.accel_truth : s.mag_truth;
    if (drift) {
      truth.tail<3>() += accel ? s.LastPoseAccBiasOffset() : s.LastPoseMagBiasOffset();
    } else {
      truth.tail<3>() += accel ? s.EffectiveAccBiasOffset() : s.EffectiveMagBiasOffset();
    }
    const Eigen::VectorXd z = (est.theta - truth).cwiseQuotient(est.sigma);
    s1 += z;
    s2 += z.cwiseAbs2();
  }
  DriftZ out;
  out.mean = s1 / runs;
  out.std = (s2 / runs - out.mean.cwiseAbs2()).cwiseMax(0).cwiseSqrt();
  return out;
}

// 150 sessions: the sample std of z scatters by 1/sqrt(300) = 0.058, so [0.8, 1.2] is a 3.5
// sigma window, and |mean z| <= 0.3 is 3.7 sigma.
TEST(DriftCalibrator, ZScoresAreUnitNormalInAnOrderedPlan) {
  for (const char* m : {"accel13", "mag13"}) {
    const DriftZ z = ZOverSessions(m, IndustrialClass(), 150, DriftOptionsForClass, true);
    for (int i = 0; i < z.std.size(); ++i) {
      EXPECT_GT(z.std[i], 0.8) << m << " parameter " << i;
      EXPECT_LT(z.std[i], 1.2) << m << " parameter " << i;
      EXPECT_LT(std::abs(z.mean[i]), 0.3) << m << " parameter " << i;
    }
  }
}

// The model before issue 19 (an independent offset per pose) on the same sessions: the drift
// poses as a scale factor (std z of Sx ~1.6) and the biases' sigma is far too large.
TEST(DriftCalibrator, IndependentOffsetsAreNotHonestInAnOrderedPlan) {
  const DriftZ z = ZOverSessions("accel13", IndustrialClass(), 150, OptionsForClass, false);
  EXPECT_GT(z.std[0], 1.3);                    // Sx
  EXPECT_LT(z.std.tail<3>().maxCoeff(), 0.8);  // biases
}

TEST(DriftCalibrator, RecordsWithoutATimeWindowAreRefused) {
  std::string error;
  auto model = MakeModel("accel13", ModelContext{}, &error);
  Calibrator c(DriftOptionsForClass(*model, IndustrialClass()));
  std::mt19937_64 rng(1);
  PoseRecord r = SimulateRecord(*model, model->nominal(), TablePose{}, IndustrialClass(), 5, &rng);
  r.t_end_s = r.t_start_s;
  EXPECT_FALSE(c.add_pose(r, &error));
  EXPECT_NE(error.find("time window"), std::string::npos) << error;
}

}  // namespace
}  // namespace turncal
