// What a calibration writes into a MIP device (daemon/device_write/device_write_plan.h, issue 23):
// the values composed with what the device stores make its new output, corrected by what stays in
// the stream, give exactly the calibration's correction of the old output (up to the f32 the device
// holds); their sigma is the covariance carried through; every refusal names its reason.
#include "daemon/device_write/device_write_plan.h"

#include <gtest/gtest.h>

#include <Eigen/LU>
#include <random>

#include "core/frames/reference.h"
#include "core/frames/table_pose.h"
#include "drivers/mip/mip_stored.h"

namespace turncal::daemon {
namespace {

using drivers::mip::StoredCalibration;

// A model's parameters off nominal by what a real sensor has: 2 % scales and gains, 10 mrad
// angles, 0.05 m/s^2, 0.05 Gauss, 0.005 rad/s biases.
Eigen::VectorXd Perturbed(const MeasurementModel& m, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> n;
  Eigen::VectorXd theta = m.nominal();
  for (int i = 0; i < m.num_parameters(); ++i) {
    const ParameterInfo& p = m.parameters()[static_cast<std::size_t>(i)];
    if (p.kind != ParameterKind::kSensor) continue;
    double s = 0.02;
    switch (p.unit) {
      case ParameterUnit::kAngle:
        s = 0.01;
        break;
      case ParameterUnit::kAcceleration:
      case ParameterUnit::kField:
        s = 0.05;
        break;
      case ParameterUnit::kAngularRate:
        s = 0.005;
        break;
      default:
        break;
    }
    theta[i] += s * n(rng);
  }
  return theta;
}

std::unique_ptr<MeasurementModel> Model(const std::string& name) {
  std::string error;
  auto m = MakeModel(name, ModelContext{}, &error);
  EXPECT_TRUE(m) << error;
  return m;
}

StoredCalibration Gx5WithMagnetometer() {
  StoredCalibration s;
  s.accel_bias = Eigen::Vector3d(0.001, -0.002, 0.0005);
  s.gyro_bias = Eigen::Vector3d::Zero();
  s.hard_iron = Eigen::Vector3d(0.01, -0.02, 0.03);
  Eigen::Matrix3d soft;
  soft << 1.01, 0.002, 0, 0.002, 0.99, -0.001, 0, -0.001, 1.0;
  s.soft_iron = soft;
  return s;
}

DeviceWriteRequest Request(const MeasurementModel* model, const Eigen::VectorXd& theta) {
  DeviceWriteRequest q;
  q.device = "imu1";
  q.serial_now = q.serial_then = "SIM0001";
  q.stored_now = Gx5WithMagnetometer();
  q.stored_then = q.stored_now;
  q.model = model;
  q.theta = theta;
  q.version = 3;
  q.gate_passed = true;
  return q;
}

const StoredWrite* Find(const DeviceWritePlan& plan, const std::string& quantity) {
  for (const StoredWrite& w : plan.writes) {
    if (w.quantity == quantity) return &w;
  }
  return nullptr;
}

Eigen::Vector3d V(const std::vector<double>& v, std::size_t at = 0) {
  return {v[at], v[at + 1], v[at + 2]};
}

TEST(DeviceWritePlan, TheMagnetometersNewOutputCorrectedByTheStreamIsTheCalibration) {
  for (const std::string name : {"mag13", "mag22"}) {
    auto model = Model(name);
    const Eigen::VectorXd theta = Perturbed(*model, 7);
    const DeviceWritePlan plan = PlanDeviceWrite(Request(model.get(), theta));
    ASSERT_TRUE(plan.ok()) << name << ": " << plan.refusals.front();
    const StoredWrite* h = Find(plan, "hard_iron_gauss");
    const StoredWrite* s = Find(plan, "soft_iron");
    ASSERT_TRUE(h && s);
    Eigen::Matrix3d S_new;
    for (int i = 0; i < 9; ++i) S_new(i / 3, i % 3) = s->to_write[static_cast<std::size_t>(i)];
    EXPECT_LT((S_new - S_new.transpose()).norm(), 0.05) << "nearly symmetric: " << name;
    const StoredCalibration old = Gx5WithMagnetometer();
    for (int k = 0; k < 20; ++k) {
      const TablePose pose{k * 0.7, k * 0.3 - 1.0, k * 1.1};
      const Eigen::Vector3d m_old = model->Predict(theta, pose);  // the output then
      const Eigen::Vector3d raw = old.soft_iron->inverse() * m_old + *old.hard_iron;
      const Eigen::Vector3d m_new = S_new * (raw - V(h->to_write));  // the device's, written
      const Eigen::Vector3d want = model->Correct(theta, m_old);
      const Eigen::Vector3d got = plan.stream.A * m_new + plan.stream.c;
      // f32 values: ~6e-8 relative on a 0.5 Gauss field.
      EXPECT_LT((got - want).norm(), 1e-6) << name << " pose " << k;
    }
    EXPECT_FALSE(plan.kept_in_stream.empty());
    EXPECT_NE(plan.kept_in_stream.front().find("rotation"), std::string::npos);
  }
}

TEST(DeviceWritePlan, TheAccelerometerAndGyroWriteTheirBiasAndKeepTheRestInTheStream) {
  for (const std::string name : {"accel13", "accel12", "gyro12", "gyro21"}) {
    auto model = Model(name);
    const Eigen::VectorXd theta = Perturbed(*model, 11);
    const DeviceWritePlan plan = PlanDeviceWrite(Request(model.get(), theta));
    ASSERT_TRUE(plan.ok()) << name << ": " << plan.refusals.front();
    ASSERT_EQ(plan.writes.size(), 1u) << name;
    const bool acc = model->sensor() == SensorKind::kAccelerometer;
    const StoredWrite& w = plan.writes.front();
    EXPECT_EQ(w.quantity, acc ? "accel_bias_g" : "gyro_bias_radps");
    const StoredCalibration old = Gx5WithMagnetometer();
    const double unit = acc ? kStandardGravity_mps2 : 1.0;
    const Eigen::Vector3d b_old = acc ? *old.accel_bias : *old.gyro_bias;
    for (int k = 0; k < 20; ++k) {
      const Eigen::Vector3d m_old =
          Eigen::Vector3d(0.3 * k - 3, 9.8 - k, 0.5 * k) * (acc ? 1 : 0.1);
      const Eigen::Vector3d raw = m_old + b_old * unit;
      const Eigen::Vector3d m_new = raw - V(w.to_write) * unit;
      const Eigen::Vector3d want = model->Correct(theta, m_old);
      const Eigen::Vector3d got = plan.stream.A * m_new + plan.stream.c;
      EXPECT_LT((got - want).norm(), 1e-6 * (1 + want.norm())) << name << " sample " << k;
    }
    ASSERT_FALSE(plan.kept_in_stream.empty());
    EXPECT_NE(plan.kept_in_stream.front().find("no command"), std::string::npos);
    EXPECT_EQ(plan.kept_in_stream.size(), name == "gyro21" ? 2u : 1u) << name;
  }
}

// With a sensor-to-vehicle transform M stored (the device outputs M (raw - b), M S (raw - h)), and
// with --transform (M_new = R M): the device's new output, as the emulator's convention computes
// it (drivers/mip/mip_stored.h), corrected by what stays in the stream, is the calibration's
// correction of the old output; with --transform the magnetometer needs no stream at all.
TEST(DeviceWritePlan, ATransformStoredOrWrittenComposesWithEveryQuantity) {
  StoredCalibration old = Gx5WithMagnetometer();
  old.transform =
      Eigen::AngleAxisd(0.09, Eigen::Vector3d(0.3, -0.5, 0.8).normalized()).toRotationMatrix();
  for (const bool transform : {false, true}) {
    for (const std::string name : {"mag13", "mag22", "accel13", "gyro12"}) {
      auto model = Model(name);
      const Eigen::VectorXd theta = Perturbed(*model, 13);
      DeviceWriteRequest q = Request(model.get(), theta);
      q.stored_now = old;
      q.stored_then = old;
      q.transform = transform;
      const DeviceWritePlan plan = PlanDeviceWrite(q);
      ASSERT_TRUE(plan.ok()) << name << ": " << plan.refusals.front();
      EXPECT_EQ(Find(plan, "sensor_to_vehicle") != nullptr, transform) << name;
      StoredCalibration now = old;
      for (const StoredWrite& w : plan.writes) {
        const std::vector<double>& v = w.to_write;
        Eigen::Matrix3d m;
        if (v.size() == 9) {
          for (int i = 0; i < 9; ++i) m(i / 3, i % 3) = v[static_cast<std::size_t>(i)];
        }
        if (w.descriptor == 0x37) now.accel_bias = V(v);
        if (w.descriptor == 0x38) now.gyro_bias = V(v);
        if (w.descriptor == 0x3A) now.hard_iron = V(v);
        if (w.descriptor == 0x3B) now.soft_iron = m;
        if (w.descriptor == 0x33) now.transform = m;
      }
      if (transform) {
        const Eigen::Matrix3d M = *now.transform;
        EXPECT_LT((M.transpose() * M - Eigen::Matrix3d::Identity()).norm(), 1e-6) << "a rotation";
      }
      const SensorKind kind = model->sensor();
      for (int k = 0; k < 12; ++k) {
        const TablePose pose{k * 0.7, k * 0.3 - 1.0, k * 1.1};
        const Eigen::Vector3d m_old = kind == SensorKind::kGyroscope
                                          ? Eigen::Vector3d(0.3 * k - 2, 0.1 * k, 1.0 - 0.2 * k)
                                          : model->Predict(theta, pose);
        Sample s;
        (kind == SensorKind::kAccelerometer ? s.acc_mps2
         : kind == SensorKind::kGyroscope   ? s.gyr_radps
                                            : s.mag) = m_old;
        drivers::mip::ReexpressMipOutput(old, now, &s);  // what the device outputs now
        const Eigen::Vector3d m_new = kind == SensorKind::kAccelerometer ? *s.acc_mps2
                                      : kind == SensorKind::kGyroscope   ? *s.gyr_radps
                                                                         : *s.mag;
        const Eigen::Vector3d want = model->Correct(theta, m_old);
        const Eigen::Vector3d got = plan.stream.A * m_new + plan.stream.c;
        EXPECT_LT((got - want).norm(), 2e-6 * (1 + want.norm()))
            << name << (transform ? " --transform" : "") << " sample " << k;
      }
      if (transform && kind == SensorKind::kMagnetometer) {
        EXPECT_LT((plan.stream.A - Eigen::Matrix3d::Identity()).norm(), 1e-12) << name;
      }
    }
  }
  // A device without the transform command refuses --transform.
  auto mag = Model("mag13");
  DeviceWriteRequest q = Request(mag.get(), Perturbed(*mag, 2));
  q.transform = true;
  const DeviceWritePlan plan = PlanDeviceWrite(q);
  ASSERT_FALSE(plan.ok());
  EXPECT_NE(plan.refusals.front().find("no sensor-to-vehicle transform command"),
            std::string::npos);
}

// Calibrations without a turntable (issue 22) write the same way: accel9's bias, gyro9's and
// gyro9g's bias (the g-sensitivity stays in the stream), magellipsoid's and magsphere's hard and
// soft iron.
TEST(DeviceWritePlan, FreeModelsComposeAsThePoseModelsDo) {
  std::mt19937 rng(17);
  std::normal_distribution<double> n(0.0, 1.0);
  FreeContext context;
  context.field_magnitude = 0.5;
  for (const std::string name : {"accel9", "gyro9", "gyro9g", "magellipsoid", "magsphere"}) {
    std::string error;
    const auto model = MakeFreeModel(name, context, &error);
    ASSERT_TRUE(model) << error;
    FreeData data;
    data.context = context;
    Eigen::VectorXd theta = model->Identity(data);  // the raw triad as it is, then perturbed
    for (Eigen::Index i = 0; i < theta.size(); ++i) theta[i] += 0.01 * n(rng);
    const SensorKind kind = model->sensor();
    const double scale = kind == SensorKind::kAccelerometer  ? context.gravity_mps2
                         : kind == SensorKind::kMagnetometer ? context.field_magnitude
                                                             : 1.0;
    DeviceWriteRequest q = Request(nullptr, theta);
    q.correction = CorrectionOf(*model, scale);
    const DeviceWritePlan plan = PlanDeviceWrite(q);
    ASSERT_TRUE(plan.ok()) << name << ": " << plan.refusals.front();
    EXPECT_EQ(plan.model, name);
    StoredCalibration now = Gx5WithMagnetometer();
    for (const StoredWrite& w : plan.writes) {
      if (w.descriptor == 0x37) now.accel_bias = V(w.to_write);
      if (w.descriptor == 0x38) now.gyro_bias = V(w.to_write);
      if (w.descriptor == 0x3A) now.hard_iron = V(w.to_write);
      if (w.descriptor == 0x3B) {
        Eigen::Matrix3d m;
        for (int i = 0; i < 9; ++i) m(i / 3, i % 3) = w.to_write[static_cast<std::size_t>(i)];
        now.soft_iron = m;
      }
    }
    for (int k = 0; k < 10; ++k) {
      const Eigen::Vector3d m_old = scale * Eigen::Vector3d(std::cos(k), std::sin(0.7 * k), 0.3);
      Sample s;
      (kind == SensorKind::kAccelerometer ? s.acc_mps2
       : kind == SensorKind::kGyroscope   ? s.gyr_radps
                                          : s.mag) = m_old;
      drivers::mip::ReexpressMipOutput(Gx5WithMagnetometer(), now, &s);
      const Eigen::Vector3d m_new = kind == SensorKind::kAccelerometer ? *s.acc_mps2
                                    : kind == SensorKind::kGyroscope   ? *s.gyr_radps
                                                                       : *s.mag;
      const Eigen::Vector3d want = model->Correct(theta, m_old);
      EXPECT_LT((plan.stream.A * m_new + plan.stream.c - want).norm(), 2e-6 * (1 + want.norm()))
          << name << " sample " << k;
    }
    EXPECT_EQ(plan.kept_in_stream.size(), name == "gyro9g" ? 2u : 1u) << name;
  }
}

TEST(DeviceWritePlan, TheSigmaOfABiasIsTheCalibrationsCarriedThrough) {
  auto model = Model("accel13");
  const Eigen::VectorXd theta = Perturbed(*model, 3);
  DeviceWriteRequest q = Request(model.get(), theta);
  const int n = model->num_parameters();
  Eigen::VectorXd sd = Eigen::VectorXd::Constant(n, 1e-5);
  const int bx = model->index_of("bx");
  ASSERT_GE(bx, 0);
  sd.segment(bx, 3) << 1e-3, 2e-3, 3e-3;  // m/s^2
  q.covariance = sd.cwiseAbs2().asDiagonal();
  const DeviceWritePlan plan = PlanDeviceWrite(q);
  ASSERT_TRUE(plan.ok());
  const std::vector<double>& sigma = plan.writes.front().sigma;
  // The bias in the measurement is the model's bias; the scales' 1e-5 add ~1e-4 m/s^2 on 9.8.
  for (int i = 0; i < 3; ++i) {
    EXPECT_NEAR(sigma[static_cast<std::size_t>(i)] * kStandardGravity_mps2, sd[bx + i],
                0.15 * sd[bx + i])
        << i;
  }
}

TEST(DeviceWritePlan, EachRefusalNamesItsReason) {
  auto mag = Model("mag13");
  const Eigen::VectorXd theta = Perturbed(*mag, 5);
  const auto reasons = [&](const std::function<void(DeviceWriteRequest*)>& change) {
    DeviceWriteRequest q = Request(mag.get(), theta);
    change(&q);
    const DeviceWritePlan plan = PlanDeviceWrite(q);
    std::string all;
    for (const std::string& r : plan.refusals) all += r + "; ";
    return all;
  };
  EXPECT_EQ(reasons([](DeviceWriteRequest*) {}), "");
  EXPECT_NE(reasons([](DeviceWriteRequest* q) {
              q->protocol = drivers::Protocol::kXbus;
            }).find("no public Xbus message"),
            std::string::npos);
  EXPECT_NE(reasons([](DeviceWriteRequest* q) {
              q->gate_passed = false;
            }).find("has not passed its gate"),
            std::string::npos);
  EXPECT_NE(reasons([](DeviceWriteRequest* q) {
              q->serial_then = "SIM0002";
            }).find("made on serial SIM0002, the device is serial SIM0001"),
            std::string::npos);
  EXPECT_NE(reasons([](DeviceWriteRequest* q) {
              (*q->stored_now.hard_iron)[1] += 1e-6;
            }).find("stores other values"),
            std::string::npos);
  EXPECT_NE(reasons([](DeviceWriteRequest* q) {
              q->stored_then.reset();
            }).find("does not record what the device stored"),
            std::string::npos);
  EXPECT_NE(reasons([](DeviceWriteRequest* q) {
              q->stored_now.soft_iron.reset();
              q->stored_then->soft_iron.reset();
            }).find("no hard- and soft-iron commands"),
            std::string::npos);
}

// accel15's second-order term is not affine: no device can hold it, and the plan says so.
TEST(DeviceWritePlan, AccelFifteensSecondOrderTermIsRefusedAsNotAffine) {
  auto accel = Model("accel15");
  Eigen::VectorXd theta = accel->nominal();
  theta[accel->index_of("K2x")] = 50e-6 / 9.80665;  // 50 ug/g^2
  AffineCorrection a;
  std::string error;
  EXPECT_FALSE(AffineCorrectionOf(*accel, theta, &a, &error));
  EXPECT_NE(error.find("accel15's correction is not affine"), std::string::npos) << error;
  // With K2 zero it is accel12's affine correction.
  theta[accel->index_of("K2x")] = 0.0;
  EXPECT_TRUE(AffineCorrectionOf(*accel, theta, &a, &error)) << error;
}

TEST(DeviceWritePlan, TheIdentitysStoredCalibrationReadsBack) {
  const nlohmann::json identity = {
      {"serial", "SIM0001"},
      {"stored_calibration",
       {{"accel_bias_g", {0.001, 0.0, -0.002}},
        {"gyro_bias_radps", {0.0, 0.0, 0.0}},
        {"hard_iron_gauss", nullptr},
        {"soft_iron", {{1.0, 0.0, 0.0}, {0.0, 1.0, 0.0}, {0.0, 0.0, 1.0}}}}}};
  const auto s = StoredCalibrationFromIdentity(identity);
  ASSERT_TRUE(s);
  ASSERT_TRUE(s->accel_bias);
  EXPECT_EQ(s->accel_bias->z(), -0.002);
  EXPECT_FALSE(s->hard_iron);
  ASSERT_TRUE(s->soft_iron);
  EXPECT_EQ(*s->soft_iron, Eigen::Matrix3d::Identity());
  EXPECT_FALSE(StoredCalibrationFromIdentity(nlohmann::json()));
}

}  // namespace
}  // namespace turncal::daemon
