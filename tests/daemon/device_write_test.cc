// What turncald keeps of a write into a device and how it verifies one
// (daemon/state/device_write_record.h): the record's round trip through the state directory, the
// history's distinct names, and the verification by measurement against windows of a simulated
// output whose noise is known.
#include "daemon/device_write/write_verification.h"
#include "daemon/state/device_write_record.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <random>

#include "core/frames/reference.h"
#include "core/sequencing/stillness.h"
#include "drivers/mip/mip_stored.h"

namespace turncal::daemon {
namespace {

namespace fs = std::filesystem;

class DeviceWrite : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() /
           ("turncal-device-write-" +
            std::to_string(::testing::UnitTest::GetInstance()->random_seed()) + "-" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  fs::path dir_;
};

StoredCalibration Factory() {
  return {Eigen::Vector3d::Zero(), Eigen::Vector3d::Zero(), Eigen::Vector3d::Zero(),
          Eigen::Matrix3d::Identity(), Eigen::Matrix3d::Identity()};
}

StoredCalibration Written() {
  StoredCalibration w = Factory();
  w.accel_bias = Eigen::Vector3d(0.00125f, -0.0025f, 0.004f);  // g, as floats
  w.hard_iron = Eigen::Vector3d(0.0123f, -0.0456f, 0.0789f);
  Eigen::Matrix3d s;
  s << 0.97f, 0.01f, -0.02f, 0.01f, 1.03f, 0.005f, -0.02f, 0.005f, 1.01f;
  w.soft_iron = s;
  return w;
}

TEST_F(DeviceWrite, TheRecordRoundTripsBitForBitAndTheHistoryNeverOverwrites) {
  DeviceWriteRecord r;
  r.device = "imu1";
  r.serial = "SIM0001";
  r.model = "mag13";
  r.version = 7;
  r.time = "2026-11-25T18:00:00Z";
  r.operation = "write";
  r.as_if = Factory();
  r.replaced = Factory();
  r.in_device = Written();
  r.saved = true;
  r.pending = Factory();
  std::string error;
  ASSERT_TRUE(WriteDeviceWriteRecord(dir_.string(), r, &error)) << error;
  DeviceWriteRecord back;
  bool exists = false;
  ASSERT_TRUE(ReadDeviceWriteRecord(dir_.string(), "imu1", &back, &exists, &error)) << error;
  ASSERT_TRUE(exists);
  EXPECT_TRUE(SameStoredCalibration(back.in_device, r.in_device));  // exact: doubles of floats
  EXPECT_TRUE(SameStoredCalibration(back.as_if, r.as_if));
  EXPECT_EQ(back.version, 7);
  EXPECT_TRUE(back.saved);
  EXPECT_TRUE(back.reexpress());
  ASSERT_TRUE(back.pending);  // a write under way when turncald stopped
  EXPECT_TRUE(SameStoredCalibration(*back.pending, Factory()));
  // None for another device; a corrupt record is an error naming the file.
  ASSERT_TRUE(ReadDeviceWriteRecord(dir_.string(), "imu2", &back, &exists, &error));
  EXPECT_FALSE(exists);
  std::ofstream(dir_ / "device_writes" / "imu2.json") << R"({"class":"DEVICE_WRITE_RECORD",)";
  EXPECT_FALSE(ReadDeviceWriteRecord(dir_.string(), "imu2", &back, &exists, &error));
  EXPECT_NE(error.find("imu2.json"), std::string::npos) << error;
  std::ofstream(dir_ / "device_writes" / "imu2.json")
      << R"({"class":"DEVICE_WRITE_RECORD","device":"imu2","serial":"S","as_if":{},)"
         R"("in_device":{"soft_iron":[[1,0,0],[0,1,0]]},"replaced":{}})";
  EXPECT_FALSE(ReadDeviceWriteRecord(dir_.string(), "imu2", &back, &exists, &error));
  EXPECT_NE(error.find("in_device"), std::string::npos) << error;
  // Three entries in one second get three files.
  std::string a, b, c;
  ASSERT_TRUE(WriteDeviceWriteHistory(dir_.string(), "imu1", {{"n", 1}}, &a, &error));
  ASSERT_TRUE(WriteDeviceWriteHistory(dir_.string(), "imu1", {{"n", 2}}, &b, &error));
  ASSERT_TRUE(WriteDeviceWriteHistory(dir_.string(), "imu1", {{"n", 3}}, &c, &error));
  EXPECT_NE(a, b);
  EXPECT_NE(b, c);
  EXPECT_TRUE(fs::exists(a) && fs::exists(b) && fs::exists(c));
}

// Windows of a still device's output (`stored` applied to a fixed raw value) with white noise of
// `sigma` per axis.
OutputWindow Window(const StoredCalibration& stored, double sigma, int n, std::mt19937* rng,
                    double t0_s) {
  std::normal_distribution<double> noise(0.0, sigma);
  const Eigen::Vector3d acc_raw(0.3, -0.2, 9.81), mag_raw(0.21, -0.05, 0.43);
  OutputWindow w;
  for (int i = 0; i < n; ++i) {
    Sample s;
    s.t_device_s = t0_s + i * 0.002;
    const Eigen::Vector3d e(noise(*rng), noise(*rng), noise(*rng));
    // The device's output with factory values is the raw value; the stored values then apply.
    s.acc_mps2 = acc_raw + e;
    s.mag = mag_raw + e * 1e-2;
    drivers::mip::ReexpressMipOutput(Factory(), stored, &s);
    w.Add(s);
  }
  return w;
}

TEST_F(DeviceWrite, AWriteTheDeviceAppliesIsVerifiedAndOneItDoesNotIsNot) {
  std::mt19937 rng(23);
  const double sigma = 0.01;  // m/s^2; the magnetometer 1e-4 Gauss
  int passed = 0;
  const int runs = 200;
  double worst_z = 0.0;
  for (int run = 0; run < runs; ++run) {
    const OutputWindow before = Window(Factory(), sigma, 500, &rng, 0.0);
    const OutputWindow after = Window(Written(), sigma, 500, &rng, 3.0);
    const nlohmann::json v = VerifyWrite(before, after, Factory(), Written(), WriteAllowance{});
    passed += v["pass"].get<bool>();
    for (const char* triad : {"acc", "mag"}) {
      for (const auto& z : v["triads"][triad]["z"])
        worst_z = std::max(worst_z, std::abs(z.get<double>()));
    }
    if (run == 0) {
      EXPECT_FALSE(v["triads"].contains("gyr"));  // the gyro's bias was not written
      EXPECT_NEAR(v["seconds_between"].get<double>(), 3.0, 1e-9);
    }
  }
  // 6 axes within VerifyZLimit(6) = 3.76: a false alarm in 0.1 % of runs (0.2 expected in 200;
  // 3 or more has a chance of 0.1 %).
  EXPECT_GE(passed, runs - 2) << "worst |z| " << worst_z;
  EXPECT_NEAR(VerifyZLimit(3), 3.59, 0.01);
  EXPECT_NEAR(VerifyZLimit(6), 3.76, 0.01);
  EXPECT_NEAR(VerifyZLimit(9), 3.87, 0.01);
  // A device that applied another hard iron (10 sigma of the means' scatter off) is caught.
  StoredCalibration wrong = Written();
  *wrong.hard_iron += Eigen::Vector3d(0.0, 10 * 1e-4 * std::sqrt(2.0 / 500), 0.0);
  const OutputWindow before = Window(Factory(), sigma, 500, &rng, 0.0);
  const OutputWindow after = Window(wrong, sigma, 500, &rng, 3.0);
  nlohmann::json v = VerifyWrite(before, after, Factory(), Written(), WriteAllowance{});
  EXPECT_FALSE(v["pass"].get<bool>()) << v.dump();
  EXPECT_NE(v["summary"].get<std::string>().find("NOT verified"), std::string::npos);
  // The bias's wander between the windows widens what is allowed.
  WriteAllowance allowance;
  allowance.wander_sigma[kTriadMag] = 1e-4;
  v = VerifyWrite(before, after, Factory(), Written(), allowance);
  EXPECT_GT(v["triads"]["mag"]["sigma"][1].get<double>(), 1e-4);
  EXPECT_TRUE(v["pass"].get<bool>()) << v.dump();
  EXPECT_NEAR(WanderSigma(0.002, 100.0, 1e9), 0.002 * std::sqrt(2.0), 1e-12);
  EXPECT_NEAR(WanderSigma(0.002, 100.0, 1.0), 0.002 * std::sqrt(2.0 * (1 - std::exp(-0.01))),
              1e-15);
  EXPECT_EQ(WanderSigma(0.0, 100.0, 5.0), 0.0);
}

// The verification at the next pose (the device moved across the write): the pose's record, in
// the station's stored values, against the calibration's prediction, both as the device outputs
// them with the written values.
TEST_F(DeviceWrite, AtTheNextPoseTheRecordIsCheckedAgainstTheCalibrationsPrediction) {
  std::string error;
  const auto model = MakeModel("mag13", ModelContext{}, &error);
  ASSERT_TRUE(model) << error;
  const Eigen::VectorXd theta = model->nominal();
  const Eigen::MatrixXd covariance = Eigen::MatrixXd::Identity(theta.size(), theta.size()) * 1e-10;
  PoseRecord record;
  record.pose.phi_rad = 0.3;
  record.pose.gamma_rad = -0.7;
  record.pose.psi_rad = 1.9;
  const double noise = 5e-4;  // per sample
  TriadStats mag;
  mag.count = 1500;
  mag.covariance = Eigen::Matrix3d::Identity() * noise * noise;
  const double sigma_mean = noise / std::sqrt(1500.0);
  mag.mean = model->Predict(theta, record.pose) + Eigen::Vector3d(1, -1, 0.5) * sigma_mean;
  record.mag = mag;
  nlohmann::json v = VerifyAtPose(*model, theta, covariance, record, Factory(), Written(), 0.0);
  EXPECT_TRUE(v["pass"].get<bool>()) << v.dump();
  // The values are the device's: the written soft and hard iron applied to the station's.
  Sample expect;
  expect.mag = mag.mean;
  drivers::mip::ReexpressMipOutput(Factory(), Written(), &expect);
  EXPECT_NEAR(v["triads"]["mag"]["measured"][0].get<double>(), expect.mag->x(), 1e-12);
  // A device whose output is 6 sigma off is not verified.
  record.mag->mean += Eigen::Vector3d(0, 6 * sigma_mean, 0);
  v = VerifyAtPose(*model, theta, covariance, record, Factory(), Written(), 0.0);
  EXPECT_FALSE(v["pass"].get<bool>()) << v.dump();
  EXPECT_NE(v["summary"].get<std::string>().find("NOT verified at the pose"), std::string::npos);
  // ... unless the bias may have wandered that far since the calibration.
  v = VerifyAtPose(*model, theta, covariance, record, Factory(), Written(), 10 * sigma_mean);
  EXPECT_TRUE(v["pass"].get<bool>()) << v.dump();
  // A window whose scatter is many times the noise says the device moved.
  std::mt19937 rng(5);
  const OutputWindow still = Window(Factory(), 0.01, 200, &rng, 0.0);
  EXPECT_FALSE(WindowMoved(still, kTriadAcc, Eigen::Vector3d::Constant(0.01)));
  EXPECT_TRUE(WindowMoved(still, kTriadAcc, Eigen::Vector3d::Constant(0.001)));
  EXPECT_FALSE(WindowMoved(still, kTriadAcc, std::nullopt));
}

}  // namespace
}  // namespace turncal::daemon
