#include "core/modeling/measurement_model.h"

#include <ceres/cost_function.h>
#include <gtest/gtest.h>

#include <random>

#include "core/modeling/accel_physical.h"

namespace turncal {
namespace {

std::unique_ptr<MeasurementModel> Make(const std::string& name, ModelContext context = {}) {
  std::string error;
  auto model = MakeModel(name, context, &error);
  EXPECT_NE(model, nullptr) << error;
  return model;
}

// phi = 90 deg, gamma = 0, psi = 90 deg: C_p^q = R1(90) R3(90) maps [x y z] to [y z x].
const TablePose kPose{M_PI / 2, 0.0, M_PI / 2};

void ExpectVectorNear(const Eigen::Vector3d& got, const Eigen::Vector3d& want, double tol) {
  for (int i = 0; i < 3; ++i) EXPECT_NEAR(got[i], want[i], tol) << "component " << i;
}

std::vector<std::string> Names(const MeasurementModel& m) {
  std::vector<std::string> names;
  for (const auto& p : m.parameters()) names.push_back(p.name);
  return names;
}

TEST(MeasurementModel, RegistryListsTheFourModelsAndThePhysicalMagnetometer) {
  const auto names = ModelNames();
  for (const char* want : {"accel12", "accel13", "mag13", "mag22", "mag-physical"}) {
    EXPECT_NE(std::find(names.begin(), names.end(), want), names.end()) << want;
  }
}

TEST(MeasurementModel, UnknownNameOrBadMountingIsAClearError) {
  std::string error;
  EXPECT_EQ(MakeModel("accel99", {}, &error), nullptr);
  EXPECT_NE(error.find("unknown model 'accel99'"), std::string::npos) << error;
  ModelContext bad;
  bad.mounting(0, 0) = 2.0;
  EXPECT_EQ(MakeModel("accel13", bad, &error), nullptr);
  EXPECT_NE(error.find("mounting"), std::string::npos) << error;
}

TEST(MeasurementModel, ParameterNamesFollowModelsMdOrder) {
  using V = std::vector<std::string>;
  EXPECT_EQ(Names(*Make("accel12")), (V{"Sx", "Sy", "Sz", "alpha1", "alpha2", "alpha3", "eps_x",
                                        "eps_y", "eps_z", "bx", "by", "bz"}));
  EXPECT_EQ(Names(*Make("accel13")), (V{"Sx", "Sy", "Sz", "alpha1", "alpha2", "alpha3", "eps_x",
                                        "eps_y", "eps_z", "beta", "bx", "by", "bz"}));
  EXPECT_EQ(Names(*Make("mag13")), (V{"g11", "g12", "g13", "g21", "g22", "g23", "g31", "g32", "g33",
                                      "beta", "bx", "by", "bz"}));
  EXPECT_EQ(Names(*Make("mag22")),
            (V{"g11", "g12", "g13", "g21", "g22",  "g23", "g31", "g32", "g33", "k11", "k12",
               "k13", "k22", "k23", "k33", "beta", "dBx", "dBy", "dBz", "bx",  "by",  "bz"}));
  EXPECT_EQ(Make("mag-physical")->num_parameters(), 22);
}

TEST(MeasurementModel, NominalAccelerometerReadsMinusGravityWhenLevel) {
  // A level sensor with z down measures specific force -g: about -9.78 m/s^2 on z.
  auto m = Make("accel13");
  const Eigen::Vector3d y = m->Predict(m->nominal(), TablePose{});
  ExpectVectorNear(y, Eigen::Vector3d(0.0167, 0.0, -9.7782), 1e-15);
}

// Hand-computed: C f = [0, -9.7782, 0.0167]; (I+S) with S = (1e-3, -2e-3, 3e-3); b added.
TEST(MeasurementModel, Accel12MatchesHandComputedValue) {
  auto m = Make("accel12");
  Eigen::VectorXd theta = m->nominal();
  theta.head<3>() << 1e-3, -2e-3, 3e-3;
  theta.tail<3>() << 0.1, -0.2, 0.3;
  ExpectVectorNear(m->Predict(theta, kPose), Eigen::Vector3d(0.1, -9.9586436, 0.3167501), 1e-12);
}

// Hand-computed: R3(90 deg) f = [0, -0.0167, -9.7782]; C of that = [-0.0167, -9.7782, 0].
TEST(MeasurementModel, Accel13MatchesHandComputedValueWithBetaNinetyDegrees) {
  auto m = Make("accel13");
  Eigen::VectorXd theta = m->nominal();
  theta.head<3>() << 1e-3, -2e-3, 3e-3;
  theta[9] = M_PI / 2;
  theta.tail<3>() << 0.1, -0.2, 0.3;
  ExpectVectorNear(m->Predict(theta, kPose), Eigen::Vector3d(0.0832833, -9.9586436, 0.3), 1e-12);
}

Eigen::VectorXd MagG() {
  Eigen::VectorXd g(9);
  g << 1.1, 0.02, -0.03, 0.01, 0.9, 0.05, -0.02, 0.04, 1.05;
  return g;
}

// Hand-computed: C B = [0.0217, 0.4004, 0.2523], then G and b.
TEST(MeasurementModel, Mag13MatchesHandComputedValue) {
  auto m = Make("mag13");
  Eigen::VectorXd theta = m->nominal();
  theta.head<9>() = MagG();
  theta.tail<3>() << 0.1, -0.2, 0.3;
  ExpectVectorNear(m->Predict(theta, kPose), Eigen::Vector3d(0.124309, 0.173192, 0.580497), 1e-12);
}

// Hand-computed: K_ C dB = K_ [0, 0, 0.1] = [0.05, 0, 0.1] with k13 = 0.5; G of it added to mag13.
TEST(MeasurementModel, Mag22MatchesHandComputedValue) {
  auto m = Make("mag22");
  Eigen::VectorXd theta = m->nominal();
  theta.head<9>() = MagG();
  theta[m->index_of("k13")] = 0.5;
  theta[m->index_of("dBx")] = 0.1;
  theta.tail<3>() << 0.1, -0.2, 0.3;
  ExpectVectorNear(m->Predict(theta, kPose), Eigen::Vector3d(0.176309, 0.178692, 0.684497), 1e-12);
}

// Hand-computed: K C B + dB = [0.24785, 0.4004, 0.26315]; (I+S) of it plus b.
TEST(MeasurementModel, MagPhysicalMatchesHandComputedValue) {
  auto m = Make("mag-physical");
  Eigen::VectorXd theta = m->nominal();
  theta.head<3>() << 1e-3, -2e-3, 3e-3;
  theta[m->index_of("k13")] = 0.5;
  theta[m->index_of("dBx")] = 0.1;
  theta.tail<3>() << 0.1, -0.2, 0.3;
  ExpectVectorNear(m->Predict(theta, kPose), Eigen::Vector3d(0.34809785, 0.1995992, 0.56393945),
                   1e-12);
}

Eigen::VectorXd RandomNearNominal(const MeasurementModel& m, std::mt19937* rng) {
  std::normal_distribution<double> n(0.0, 1.0);
  Eigen::VectorXd theta = m.nominal();
  for (int i = 0; i < theta.size(); ++i) {
    const auto& p = m.parameters()[i];
    const double scale = p.name == "beta" ? 0.3 : p.unit == ParameterUnit::kAngle ? 2e-3 : 2e-2;
    theta[i] += scale * n(*rng);
  }
  return theta;
}

TEST(MeasurementModel, AutomaticJacobianMatchesCentralDifferences) {
  std::mt19937 rng(7);
  for (const auto& name : ModelNames()) {
    auto m = Make(name);
    const Eigen::VectorXd theta = RandomNearNominal(*m, &rng);
    const TablePose pose{0.3, -0.7, 2.1};
    Jacobian3 J;
    const Eigen::Vector3d y = m->Predict(theta, pose, &J);
    ExpectVectorNear(y, m->Predict(theta, pose), 1e-15);
    ASSERT_EQ(J.cols(), m->num_parameters());
    for (int i = 0; i < m->num_parameters(); ++i) {
      const double h = 1e-6;
      Eigen::VectorXd plus = theta, minus = theta;
      plus[i] += h;
      minus[i] -= h;
      const Eigen::Vector3d fd = (m->Predict(plus, pose) - m->Predict(minus, pose)) / (2 * h);
      // Central differences err by O(h^2 |y'''|) plus rounding O(eps |y| / h) ~ 1e-9.
      for (int r = 0; r < 3; ++r) EXPECT_NEAR(J(r, i), fd[r], 1e-7) << name << " " << i;
    }
  }
}

TEST(MeasurementModel, ResidualIsWhitenedPredictionMinusMeasurement) {
  auto m = Make("accel13");
  std::mt19937 rng(8);
  const Eigen::VectorXd theta = RandomNearNominal(*m, &rng);
  const TablePose pose{1.0, 0.2, -0.5};
  const Eigen::Vector3d measured(0.3, -1.0, -9.0);
  Eigen::Matrix3d sqrt_info = Eigen::Matrix3d::Zero();
  sqrt_info.diagonal() << 100, 200, 300;
  auto cost = m->MakeResidual(pose, measured, sqrt_info);
  Eigen::Vector3d r;
  const double* params[] = {theta.data()};
  ASSERT_TRUE(cost->Evaluate(params, r.data(), nullptr));
  ExpectVectorNear(r, sqrt_info * (m->Predict(theta, pose) - measured), 1e-12);
}

// The correction inverts the sensor: corrected(predicted measurement) equals the true excitation
// in the output frame.
TEST(MeasurementModel, CorrectionRecoversTheExcitationInItsFrame) {
  std::mt19937 rng(9);
  for (const auto& name : ModelNames()) {
    for (OutputFrame frame : {OutputFrame::kCase, OutputFrame::kTable}) {
      ModelContext context;
      context.accel_output_frame = frame;
      context.mounting = AxisAlignedRotations()[5];
      auto m = Make(name, context);
      Eigen::VectorXd theta = RandomNearNominal(*m, &rng);
      const TablePose pose{-0.4, 0.9, 1.3};
      const double beta = m->index_of("beta") >= 0 ? theta[m->index_of("beta")] : 0.0;
      Eigen::Vector3d truth_q = pose.C_p_q() * C_ned_p(beta) * m->excitation_ned();
      if (name == "mag22") {
        // dB is a table field: the corrected field in q includes K_ C_p^q dB.
        const Eigen::Vector3d dB = theta.segment<3>(m->index_of("dBx"));
        Mat3<double> K;
        const double* k = theta.data() + m->index_of("k11");
        K << k[0], k[1], k[2], k[1], k[3], k[4], k[2], k[4], k[5];
        truth_q += K * pose.C_p_q() * dB;
      }
      Eigen::Vector3d truth = truth_q;
      if (m->corrected_frame() == OutputFrame::kCase) {
        const Eigen::Vector3d eps = theta.segment<3>(m->index_of("eps_x"));
        truth = C_q_r(eps.x(), eps.y(), eps.z(), context.mounting) * truth_q;
      }
      // A gyroscope's g-sensitivity needs the specific force in q; the other models ignore it.
      const Eigen::Vector3d f_q = pose.C_p_q() * SpecificForceNed(context.reference);
      ExpectVectorNear(m->CorrectWithForce(theta, m->Predict(theta, pose), f_q), truth, 1e-12);
    }
  }
}

TEST(MeasurementModel, LinearStartOfAccelerometerRecoversPhysicalParameters) {
  auto m = Make("accel13");
  std::mt19937 rng(10);
  const Eigen::VectorXd theta = RandomNearNominal(*m, &rng);
  AccelPhysical p;
  p.S = theta.segment<3>(0);
  p.alpha = theta.segment<3>(3);
  p.eps = theta.segment<3>(6);
  Eigen::VectorXd back;
  std::string error;
  ASSERT_TRUE(m->FromLinear(AccelGFromPhysical(p, m->context().mounting), theta[9], theta.tail<3>(),
                            &back, &error))
      << error;
  EXPECT_LT((back - theta).cwiseAbs().maxCoeff(), 1e-12);
}

}  // namespace
}  // namespace turncal
