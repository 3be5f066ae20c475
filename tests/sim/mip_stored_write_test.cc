// Writing a stored calibration into a MIP device (drivers/mip/mip_stored_write.h, issue 23),
// against the emulated device (sim/device.h) that holds, saves and applies it: written, read back
// bit for bit and saved; a reply lost once is retried; a NACK mid-sequence (a save the device's
// storage refuses) rolls back to the old values, verified; a device that stops answering
// mid-write leaves a state reported as unknown, with every step in the log.
#include "drivers/mip/mip_stored_write.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <deque>
#include <filesystem>

#include "drivers/mip/mip_encoder.h"
#include "sim/device.h"
#include "tests/support/virtual_link.h"

namespace turncal::sim {
namespace {

using Bytes = std::vector<std::uint8_t>;
namespace mip = drivers::mip;

// The host's link to the emulated device on a virtual clock, streaming while the device streams;
// replies can be lost: the `lose`-th command to 3DM descriptor `lose_descriptor` (1-based, counted
// over retries too) and, with `silent_after`, every reply after that many commands.
class LossyLink : public testing_support::VirtualClockLink {
 public:
  explicit LossyLink(DeviceEmulator* device) : device_(device) {}
  std::uint8_t lose_descriptor = 0;
  int lose = 0;
  int silent_after = -1;
  int commands = 0;

  bool Write(std::span<const std::uint8_t> bytes, std::string*) override {
    ++commands;
    const Bytes reply = device_->OnHostBytes(bytes);
    const bool to_lose_descriptor =
        bytes.size() > 5 && bytes[2] == 0x0C && bytes[5] == lose_descriptor;
    if (to_lose_descriptor && --lose == 0) return true;  // the device did it; the reply is lost
    if (silent_after >= 0 && commands > silent_after) return true;
    if (device_->streaming()) Queue(mip::SensorPacket(StreamSample()));
    Queue(reply);
    return true;
  }

 private:
  static Sample StreamSample() {
    Sample s;
    s.t_device_s = 1.0;
    s.acc_mps2 = Eigen::Vector3d(0, 0, -9.8);
    s.gyr_radps = Eigen::Vector3d::Zero();
    s.mag = Eigen::Vector3d(0.2, 0, 0.4);
    return s;
  }
  DeviceEmulator* device_;
};

const drivers::ExchangeOptions kOptions{std::chrono::milliseconds(50), 3};

EmulatedIdentity Identity(const std::string& nonvolatile_path) {
  EmulatedIdentity id;
  id.mip_stored.hard_iron = Eigen::Vector3d(0.01, 0.02, 0.03);
  id.mip_stored.soft_iron = Eigen::Matrix3d::Identity();
  id.mip_nonvolatile_path = nonvolatile_path;
  return id;
}

// The new magnetometer values (0.1 / 3 is not a float: the read-back must compare floats).
std::vector<mip::StoredWriteStep> MagnetometerSteps() {
  return {{0x3A, {0.1 / 3, -0.02, 0.05}, {0.01, 0.02, 0.03}},
          {0x3B, {1.02, 0.01, 0, 0.01, 0.98, 0, 0, 0, 1.0}, {1, 0, 0, 0, 1, 0, 0, 0, 1}}};
}

class MipStoredWrite : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = std::filesystem::temp_directory_path() /
           ("mip_stored_write_test." + std::to_string(::getpid()) + "." +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    std::filesystem::create_directories(dir_);
  }
  void TearDown() override { std::filesystem::remove_all(dir_); }
  std::string Nvm() const { return (dir_ / "SIM0001.nvm.json").string(); }
  std::filesystem::path dir_;
};

TEST_F(MipStoredWrite, WritesReadsBackBitForBitSavesAndTheRestartedDeviceHasIt) {
  {
    auto device = DeviceEmulator::Make(drivers::Protocol::kMip, Identity(Nvm()), 100);
    LossyLink link(device.get());
    mip::Dialogue dialogue(&link, kOptions);
    const auto out = mip::WriteStoredCalibration(&dialogue, MagnetometerSteps(), true);
    EXPECT_EQ(out.state, mip::StoredWriteState::kSaved) << out.error;
    EXPECT_TRUE(out.error.empty()) << out.error;
    ASSERT_TRUE(out.read_back);
    EXPECT_EQ(out.read_back->hard_iron->x(), static_cast<float>(0.1 / 3));
    EXPECT_TRUE(device->streaming());  // resumed
    EXPECT_EQ(out.log.back(), "resume: ok");
  }
  auto restarted = DeviceEmulator::Make(drivers::Protocol::kMip, Identity(Nvm()), 100);
  EXPECT_EQ(restarted->mip_stored()->hard_iron->x(), static_cast<float>(0.1 / 3));
  EXPECT_EQ((*restarted->mip_stored()->soft_iron)(1, 1), static_cast<float>(0.98));
}

TEST_F(MipStoredWrite, WithoutSaveTheRestartedDeviceHasTheOldValues) {
  {
    auto device = DeviceEmulator::Make(drivers::Protocol::kMip, Identity(Nvm()), 100);
    LossyLink link(device.get());
    mip::Dialogue dialogue(&link, kOptions);
    const auto out = mip::WriteStoredCalibration(&dialogue, MagnetometerSteps(), false);
    EXPECT_EQ(out.state, mip::StoredWriteState::kWritten) << out.error;
    EXPECT_EQ(device->mip_stored()->hard_iron->x(), static_cast<float>(0.1 / 3));
  }
  auto restarted = DeviceEmulator::Make(drivers::Protocol::kMip, Identity(Nvm()), 100);
  EXPECT_EQ(restarted->mip_stored()->hard_iron->x(), 0.01);
}

TEST_F(MipStoredWrite, AReplyLostOnceIsRetried) {
  auto device = DeviceEmulator::Make(drivers::Protocol::kMip, Identity(Nvm()), 100);
  LossyLink link(device.get());
  link.lose_descriptor = 0x3B;
  link.lose = 1;  // the soft iron's write: done by the device, its reply lost, sent again
  mip::Dialogue dialogue(&link, kOptions);
  const auto out = mip::WriteStoredCalibration(&dialogue, MagnetometerSteps(), true);
  EXPECT_EQ(out.state, mip::StoredWriteState::kSaved) << out.error;
}

TEST_F(MipStoredWrite, ANackMidSequenceRollsBackToTheOldValues) {
  // The storage's folder is missing: the device refuses the save with NACK 4 "failed".
  const std::string nvm = (dir_ / "gone" / "SIM0001.nvm.json").string();
  auto device = DeviceEmulator::Make(drivers::Protocol::kMip, Identity(nvm), 100);
  LossyLink link(device.get());
  mip::Dialogue dialogue(&link, kOptions);
  const auto out = mip::WriteStoredCalibration(&dialogue, MagnetometerSteps(), true);
  EXPECT_EQ(out.state, mip::StoredWriteState::kRolledBack);
  EXPECT_NE(out.error.find("NACK 4 (failed)"), std::string::npos) << out.error;
  EXPECT_EQ(*device->mip_stored()->hard_iron,
            Eigen::Vector3d(0.01, 0.02, 0.03).cast<float>().cast<double>());
  EXPECT_EQ(*device->mip_stored()->soft_iron, Eigen::Matrix3d::Identity());
  EXPECT_TRUE(device->streaming());
  std::string log;
  for (const std::string& l : out.log) log += l + "\n";
  EXPECT_NE(log.find("rollback: read back: the old values, bit for bit"), std::string::npos) << log;
}

TEST_F(MipStoredWrite, ADeviceThatStopsAnsweringMidWriteLeavesAStateReportedUnknown) {
  auto device = DeviceEmulator::Make(drivers::Protocol::kMip, Identity(Nvm()), 100);
  LossyLink link(device.get());
  link.silent_after = 2;  // set to idle, the hard iron's write; then nothing comes back
  mip::Dialogue dialogue(&link, kOptions);
  const auto out = mip::WriteStoredCalibration(&dialogue, MagnetometerSteps(), true);
  EXPECT_EQ(out.state, mip::StoredWriteState::kUnknown);
  EXPECT_FALSE(out.error.empty());
  EXPECT_FALSE(out.rollback_error.empty());
  std::string log;
  for (const std::string& l : out.log) log += l + "\n";
  EXPECT_NE(log.find("write hard-iron offset: ok"), std::string::npos) << log;
  EXPECT_NE(log.find("rollback: write the old hard-iron offset"), std::string::npos) << log;
  // Nothing was saved: the restarted device has the old values.
  auto restarted = DeviceEmulator::Make(drivers::Protocol::kMip, Identity(Nvm()), 100);
  EXPECT_EQ(restarted->mip_stored()->hard_iron->x(), 0.01);
}

TEST_F(MipStoredWrite, AFirstWriteRefusedLeavesTheDeviceUnchanged) {
  // A device without the magnetometer's commands: NACK 1 to 0x3A.
  EmulatedIdentity id;
  id.mip_stored.hard_iron.reset();
  id.mip_stored.soft_iron.reset();
  id.mip_nonvolatile_path = Nvm();
  auto device = DeviceEmulator::Make(drivers::Protocol::kMip, id, 100);
  LossyLink link(device.get());
  mip::Dialogue dialogue(&link, kOptions);
  const auto out = mip::WriteStoredCalibration(&dialogue, MagnetometerSteps(), false);
  EXPECT_EQ(out.state, mip::StoredWriteState::kUnchanged) << out.rollback_error;
  EXPECT_NE(out.error.find("NACK 1 (unknown command)"), std::string::npos) << out.error;
}

}  // namespace
}  // namespace turncal::sim
