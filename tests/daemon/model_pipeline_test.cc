// The corrected output's sigma (daemon/station/model_pipeline.h): a gyroscope's g-sensitivity comes
// off the raw rate with the specific force, so B_g's uncertainty is in the corrected rate's sigma.

#include "daemon/station/model_pipeline.h"

#include <gtest/gtest.h>

#include <cmath>

#include "daemon/station/station.h"

namespace turncal::daemon {
namespace {

TEST(ModelPipelineCorrection, Gyro21SigmaCarriesTheGSensitivitysCovariance) {
  StationOptions options;
  options.drift_model = false;
  ModelPipeline m = ModelPipeline::Make("gyro21", options, IndustrialClass());
  ASSERT_TRUE(m.model);
  const Eigen::VectorXd theta = m.model->nominal();
  const int n = m.model->num_parameters();
  // Only Bg_xz (x's response to force along q's z) is uncertain: 1e-5 rad/s per m/s^2.
  Eigen::MatrixXd covariance = Eigen::MatrixXd::Zero(n, n);
  const int xz = m.model->index_of("Bg_xz");
  ASSERT_GE(xz, 0);
  covariance(xz, xz) = 1e-10;
  m.Apply(1, theta, covariance, std::nullopt, BiasDrift{});
  const Eigen::Vector3d raw(0.1, -0.2, 0.05);
  const Eigen::Vector3d f_q(0.0, 0.0, -9.81);
  std::optional<Eigen::Vector3d> sigma;
  m.Correct(raw, 0.0, &sigma, &f_q);
  ASSERT_TRUE(sigma);
  // The nominal G is the identity (no mounting): sigma_x = 1e-5 x 9.81, the others 0.
  EXPECT_NEAR((*sigma)[0], 9.81e-5, 1e-8);
  EXPECT_NEAR((*sigma)[1], 0.0, 1e-9);
  EXPECT_NEAR((*sigma)[2], 0.0, 1e-9);
  // Without the force there is nothing for B_g to act on.
  m.Correct(raw, 0.0, &sigma, nullptr);
  ASSERT_TRUE(sigma);
  EXPECT_NEAR(sigma->norm(), 0.0, 1e-9);
}

}  // namespace
}  // namespace turncal::daemon
