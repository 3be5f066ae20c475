#include "core/analysis/observability.h"

#include <gtest/gtest.h>

#include <Eigen/QR>
#include <algorithm>
#include <cmath>
#include <set>

#include "core/estimation/calibrator.h"
#include "core/modeling/mag22_gauge.h"
#include "sim/synthetic.h"

namespace turncal {
namespace {

std::unique_ptr<MeasurementModel> Model(const std::string& name) {
  std::string error;
  auto model = MakeModel(name, ModelContext{}, &error);
  EXPECT_NE(model, nullptr) << error;
  return model;
}

// How much of `v` lies outside the column span of `basis` (both in the same coordinates),
// relative to |v|.
double OutsideSpan(const Eigen::MatrixXd& basis, const Eigen::VectorXd& v) {
  const Eigen::MatrixXd Q =
      basis.householderQr().householderQ() * Eigen::MatrixXd::Identity(basis.rows(), basis.cols());
  return (v - Q * (Q.transpose() * v)).norm() / v.norm();
}

Eigen::MatrixXd NullBasisRaw(const RankAnalysis& a, int N) {
  Eigen::MatrixXd basis(N, static_cast<Eigen::Index>(a.null.size()));
  for (std::size_t i = 0; i < a.null.size(); ++i)
    basis.col(static_cast<Eigen::Index>(i)) = a.null[i].coefficients;
  return basis;
}

// --- Structural ranks (MODELS.md "Observability" table) ---------------------------------------

struct StructuralCase {
  const char* model;
  int rank;
};

class StructuralRank : public ::testing::TestWithParam<StructuralCase> {};

TEST_P(StructuralRank, MatchesTheIndependentCheckAtSeveralGenericPoints) {
  const auto& c = GetParam();
  auto model = Model(c.model);
  for (std::uint64_t seed : {1, 2, 3}) {
    std::mt19937_64 rng(seed);
    const StructuralReport r =
        AnalyzeStructure(*model, GenericParameterPoint(*model, &rng), ObservabilityOptions{});
    EXPECT_EQ(r.analysis.rank, c.rank) << c.model << " seed " << seed;
    EXPECT_EQ(static_cast<int>(r.analysis.null.size()), model->num_parameters() - c.rank);
    // A clean gap: the rank does not depend on the tolerance within six orders of magnitude.
    if (c.rank < model->num_parameters()) {
      EXPECT_LT(r.analysis.relative_singular[c.rank], 1e-13);
    }
    EXPECT_GT(r.analysis.relative_singular[c.rank - 1], 1e-4);
  }
}

INSTANTIATE_TEST_SUITE_P(Models, StructuralRank,
                         ::testing::Values(StructuralCase{"accel12", 12},
                                           StructuralCase{"accel13", 13},
                                           StructuralCase{"mag13", 13},
                                           StructuralCase{"mag-physical", 13},
                                           StructuralCase{"mag22", 21}),
                         [](const auto& test_info) {
                           std::string name = test_info.param.model;
                           std::replace(name.begin(), name.end(), '-', '_');
                           return name;
                         });

TEST(Structural, ExtendedVectorSizesFollowTheSeed) {
  std::mt19937_64 rng(4);
  for (const auto& [name, size] : std::vector<std::pair<std::string, int>>{
           {"accel12", 30}, {"accel13", 30}, {"mag13", 30}, {"mag-physical", 30}, {"mag22", 57}}) {
    auto model = Model(name);
    Eigen::MatrixXd J;
    const Eigen::VectorXd e = model->Extended(GenericParameterPoint(*model, &rng), &J);
    EXPECT_EQ(e.size(), size) << name;
    EXPECT_EQ(J.rows(), size);
    EXPECT_EQ(J.cols(), model->num_parameters());
  }
}

TEST(Structural, ExtendedJacobianMatchesCentralDifferences) {
  std::mt19937_64 rng(5);
  for (const auto& name : {"accel13", "mag22", "mag-physical"}) {
    auto model = Model(name);
    const Eigen::VectorXd theta = GenericParameterPoint(*model, &rng);
    Eigen::MatrixXd J;
    model->Extended(theta, &J);
    const double h = 1e-6;
    for (int j = 0; j < model->num_parameters(); ++j) {
      Eigen::VectorXd plus = theta, minus = theta;
      plus[j] += h;
      minus[j] -= h;
      const Eigen::VectorXd numeric =
          (model->Extended(plus, nullptr) - model->Extended(minus, nullptr)) / (2 * h);
      EXPECT_LT((numeric - J.col(j)).cwiseAbs().maxCoeff(), 1e-7) << name << " column " << j;
    }
  }
}

TEST(Structural, Mag22NullDirectionIsTheScaleOfKAgainstDeltaB) {
  auto model = Model("mag22");
  std::mt19937_64 rng(6);
  const Eigen::VectorXd theta = GenericParameterPoint(*model, &rng);
  const StructuralReport r = AnalyzeStructure(*model, theta, ObservabilityOptions{});
  ASSERT_EQ(r.analysis.null.size(), 1u);
  const Eigen::MatrixXd analytic = Mag22NullDirections(*model, theta);
  // Direction 1 (K_ -> lambda K_, dB -> dB / lambda) is the structural null direction ...
  EXPECT_LT(OutsideSpan(NullBasisRaw(r.analysis, 22), analytic.col(0)), 1e-9);
  // ... direction 2 changes H' (it is invisible only to the data, see below).
  EXPECT_GT(OutsideSpan(NullBasisRaw(r.analysis, 22), analytic.col(1)), 0.1);
  const auto& named = r.analysis.null[0].involved;
  for (const char* k : {"k11", "k22", "k33"}) {
    EXPECT_NE(std::find(named.begin(), named.end(), k), named.end()) << k;
  }
  EXPECT_NE(r.analysis.null[0].text.find("k11"), std::string::npos);
}

// --- Data level --------------------------------------------------------------------------------

std::vector<WeightedPose> Weighted(const MeasurementModel& model,
                                   const std::vector<TablePose>& poses, const SensorClass& sensor,
                                   double dwell_s = 5.0) {
  const CalibratorOptions o = OptionsForClass(model, sensor);
  const Eigen::Matrix3d W = ExpectedSqrtInformation(o.noise_density, o.pose_offset_sigma, dwell_s);
  std::vector<WeightedPose> out;
  for (const auto& p : poses) out.push_back({p, Eigen::Vector3d::Zero(), W, nullptr});
  return out;
}

struct DataCase {
  const char* model;
  int rank;
};

class DataRank : public ::testing::TestWithParam<DataCase> {};

TEST_P(DataRank, DiversePosesReachTheIdentifiableRank) {
  const auto& c = GetParam();
  auto model = Model(c.model);
  for (std::uint64_t seed : {1, 2, 3}) {
    std::mt19937_64 rng(seed);
    const Eigen::VectorXd theta = DrawTruth(*model, ConsumerClass(), &rng);
    const DataReport r =
        AnalyzeData(*model, theta, Weighted(*model, RandomPoses(60, &rng), ConsumerClass()),
                    ObservabilityOptions{});
    EXPECT_EQ(r.analysis.rank, c.rank) << c.model << " seed " << seed;
    EXPECT_EQ(r.expected_rank, c.rank);
    EXPECT_EQ(r.diversity.regressor_rank, 10);
    EXPECT_TRUE(r.diversity.findings.empty());
    for (int i = 0; i < r.sigma.size(); ++i) EXPECT_TRUE(std::isfinite(r.sigma[i])) << i;
  }
}

INSTANTIATE_TEST_SUITE_P(Models, DataRank,
                         ::testing::Values(DataCase{"accel12", 12}, DataCase{"accel13", 13},
                                           DataCase{"mag13", 13}, DataCase{"mag22", 20}),
                         [](const auto& test_info) { return std::string(test_info.param.model); });

TEST(Data, Mag22NullSpaceIsSpannedByBothGaugeDirections) {
  auto model = Model("mag22");
  for (std::uint64_t seed : {1, 2, 3}) {
    std::mt19937_64 rng(seed);
    const Eigen::VectorXd theta = GenericParameterPoint(*model, &rng);
    const DataReport r =
        AnalyzeData(*model, theta, Weighted(*model, RandomPoses(40, &rng), IndustrialClass()),
                    ObservabilityOptions{});
    ASSERT_EQ(r.analysis.null.size(), 2u);
    const Eigen::MatrixXd analytic = Mag22NullDirections(*model, theta);
    const Eigen::MatrixXd numeric = NullBasisRaw(r.analysis, 22);
    for (int k = 0; k < 2; ++k) {
      EXPECT_LT(OutsideSpan(numeric, analytic.col(k)), 1e-8) << "direction " << k + 1;
    }
    // and conversely: nothing in the numerical null space outside the analytic pair.
    for (int k = 0; k < 2; ++k) {
      EXPECT_LT(OutsideSpan(analytic, numeric.col(k)), 1e-8);
    }
    EXPECT_FALSE(r.gauge.empty());
  }
}

TEST(Data, AboutOneAxisOnlyLosesFourDirectionsAndSaysWhy) {
  auto model = Model("accel13");
  std::mt19937_64 rng(7);
  const Eigen::VectorXd theta = DrawTruth(*model, IndustrialClass(), &rng);
  const DataReport r = AnalyzeData(
      *model, theta, Weighted(*model, AboutZPoses(12), IndustrialClass()), ObservabilityOptions{});
  EXPECT_EQ(r.analysis.rank, 9);
  ASSERT_EQ(r.analysis.null.size(), 4u);
  EXPECT_EQ(r.diversity.distinct_down, 1);
  EXPECT_LT(r.diversity.regressor_rank, 10);
  ASSERT_FALSE(r.diversity.findings.empty());
  EXPECT_NE(r.diversity.findings[0].find("psi axis"), std::string::npos) << r.diversity.findings[0];
  // The biases cannot be told from the sensor's response along down; beta from eps_z.
  std::set<std::string> involved;
  for (const auto& d : r.analysis.null) involved.insert(d.involved.begin(), d.involved.end());
  for (const char* p : {"bx", "by", "bz", "beta", "eps_z"}) EXPECT_TRUE(involved.count(p)) << p;
  EXPECT_TRUE(std::isinf(r.sigma[model->index_of("bz")]));
}

TEST(Data, TurningAboutTheInnerAxisOnlyIsReportedAsOneAxis) {
  std::vector<TablePose> poses;
  for (int i = 0; i < 12; ++i) poses.push_back(TablePose{2 * M_PI * i / 12, 0.3, 0.0});
  const PoseDiversity d =
      AnalyzePoseDiversity(poses, Eigen::Vector3d(0.0167, 0, 9.8), ObservabilityOptions{});
  EXPECT_GT(d.distinct_down, 1);
  ASSERT_FALSE(d.findings.empty());
  EXPECT_NE(d.findings[0].find("single axis"), std::string::npos) << d.findings[0];
}

TEST(Data, BetaIsTwoOrdersOfMagnitudeWeakerThanTheOtherAngles) {
  // MODELS.md: beta is seen only through g_N = -0.0167 m/s^2; at 60 poses with 2 mm/s^2 per-pose
  // noise sigma_beta ~ 0.016 rad while the other angles are ~6e-5 rad.
  auto model = Model("accel13");
  std::mt19937_64 rng(8);
  const Eigen::VectorXd theta = DrawTruth(*model, IndustrialClass(), &rng);
  std::vector<WeightedPose> poses;
  for (const auto& p : RandomPoses(60, &rng)) {
    poses.push_back({p, Eigen::Vector3d::Zero(), Eigen::Matrix3d::Identity() / 2e-3, nullptr});
  }
  const DataReport r = AnalyzeData(*model, theta, poses, ObservabilityOptions{});
  const double sigma_beta = r.sigma[model->index_of("beta")];
  EXPECT_GT(sigma_beta, 0.010);
  EXPECT_LT(sigma_beta, 0.025);
  double other = 0;
  for (const char* a : {"alpha1", "alpha2", "alpha3", "eps_x", "eps_y", "eps_z"}) {
    other = std::max(other, r.sigma[model->index_of(a)]);
  }
  EXPECT_GT(other, 3e-5);
  EXPECT_LT(other, 1.2e-4);
  EXPECT_GT(sigma_beta / other, 100.0);
  // The structural test cannot see this: in theta^e beta scales whole blocks of H'.
  const StructuralReport s = AnalyzeStructure(*model, theta, ObservabilityOptions{});
  ASSERT_FALSE(r.analysis.weak.empty());
  EXPECT_EQ(r.analysis.weak.back().involved.front(), "beta");
  EXPECT_NE(s.analysis.weak.back().involved.front(), "beta");
}

TEST(Data, CramerRaoSigmaEqualsTheCalibratorsCovariance) {
  for (const char* name : {"accel13", "mag13", "mag22"}) {
    auto model = Model(name);
    std::mt19937_64 rng(9);
    const SensorClass sensor = IndustrialClass();
    const Eigen::VectorXd truth = DrawTruth(*model, sensor, &rng);
    CalibratorOptions options = OptionsForClass(*model, sensor);
    options.inflate_covariance_by_chi2 = false;
    Calibrator calibrator(options);
    for (const auto& p : RandomPoses(40, &rng)) {
      ASSERT_TRUE(
          calibrator.add_pose(SimulateRecord(*model, truth, p, sensor, 5.0, &rng), nullptr));
    }
    const Estimate e = calibrator.solve();
    ASSERT_TRUE(e.ok) << e.error;
    const DataReport r =
        AnalyzeData(*model, e.theta, calibrator.weighted_poses(), ObservabilityOptions{});
    for (int i = 0; i < model->num_parameters(); ++i) {
      EXPECT_NEAR(r.sigma[i] / e.sigma[i], 1.0, 1e-3) << name << " " << e.parameters[i].name;
    }
  }
}

TEST(Options, RejectNonsense) {
  ObservabilityOptions o;
  std::string error;
  EXPECT_TRUE(o.IsValid(&error));
  o.rank_tolerance = 0;
  EXPECT_FALSE(o.IsValid(&error));
  o = ObservabilityOptions{};
  o.weak_ratio = 1e-12;
  EXPECT_FALSE(o.IsValid(&error));
  EXPECT_FALSE(error.empty());
}

}  // namespace
}  // namespace turncal
