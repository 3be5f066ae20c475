// An emulated MIP device's stored calibration (sim/mip_storage.h, issue 23): what the host
// writes is read back bit for bit and applied to the output in the device's convention; save
// keeps it in the non-volatile file, which a new emulator (the device restarted) powers up with;
// load and default put the startup and factory values back in use; a storage that cannot be
// written refuses the save with NACK 4; a corrupt one is reported and not used.
#include "sim/mip_storage.h"

#include <gtest/gtest.h>

#include <unistd.h>
#include <Eigen/Geometry>
#include <limits>

#include <filesystem>
#include <fstream>

#include "core/frames/reference.h"
#include "drivers/bytes.h"
#include "drivers/mip/mip_encoder.h"
#include "drivers/mip/mip_stored.h"
#include "sim/device.h"

namespace turncal::sim {
namespace {

using Bytes = std::vector<std::uint8_t>;
namespace mip = drivers::mip;

struct Answer {
  std::uint8_t code = 0xFF;
  Bytes data;  // the reply data field's data, if any
};

// One command to the device; its one reply packet parsed (ACK/NACK field, then a data field).
Answer Send(DeviceEmulator* device, const Bytes& command) {
  const Bytes r = device->OnHostBytes(command);
  Answer a;
  if (r.size() < 10 || r[4] != 0x04 || r[5] != 0xF1) return a;
  a.code = r[7];
  if (r.size() > 10 && r[8] >= 2) a.data.assign(r.begin() + 10, r.begin() + 8 + r[8]);
  return a;
}

std::vector<float> Floats(const Bytes& data) {
  std::vector<float> out;
  for (std::size_t i = 0; i + 4 <= data.size(); i += 4) {
    out.push_back(static_cast<float>(drivers::LoadF32(data.data() + i)));
  }
  return out;
}

EmulatedIdentity WithMagnetometerCommands() {
  EmulatedIdentity id;
  id.mip_stored.hard_iron = Eigen::Vector3d::Zero();
  id.mip_stored.soft_iron = Eigen::Matrix3d::Identity();
  return id;
}

class MipStorage : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = std::filesystem::temp_directory_path() /
           ("mip_storage_test." + std::to_string(::getpid()) + "." +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    std::filesystem::create_directories(dir_);
  }
  void TearDown() override { std::filesystem::remove_all(dir_); }
  std::filesystem::path dir_;
};

const std::vector<double> kHardIron = {0.0123, -0.0456, 0.0789};
const std::vector<double> kSoftIron = {1.02, 0.01, -0.02, 0.01, 0.97, 0.03, -0.02, 0.03, 1.05};
const std::vector<double> kAccelBias = {0.0011, -0.0022, 0.0033};

TEST_F(MipStorage, WrittenValuesReadBackBitForBitAndCorrectTheOutput) {
  auto device = DeviceEmulator::Make(drivers::Protocol::kMip, WithMagnetometerCommands(), 100);
  ASSERT_EQ(Send(device.get(), mip::WriteStored(0x3A, kHardIron)).code, 0);
  ASSERT_EQ(Send(device.get(), mip::WriteStored(0x3B, kSoftIron)).code, 0);
  ASSERT_EQ(Send(device.get(), mip::WriteStored(0x37, kAccelBias)).code, 0);
  // A sensor-to-vehicle transform: 0.1 rad about (1, 2, 2)/3, as floats.
  const Eigen::Matrix3d rotation =
      Eigen::AngleAxisd(0.1, Eigen::Vector3d(1, 2, 2) / 3.0).toRotationMatrix();
  std::vector<double> dcm;
  for (int i = 0; i < 9; ++i) dcm.push_back(static_cast<float>(rotation(i / 3, i % 3)));
  ASSERT_EQ(Send(device.get(), mip::WriteStored(0x33, dcm)).code, 0);
  const Answer h = Send(device.get(), mip::ReadStored(0x3A));
  ASSERT_EQ(h.code, 0);
  const std::vector<float> hard = Floats(h.data);
  ASSERT_EQ(hard.size(), 3u);
  for (int i = 0; i < 3; ++i) EXPECT_EQ(hard[i], static_cast<float>(kHardIron[i]));  // bit for bit
  const std::vector<float> soft = Floats(Send(device.get(), mip::ReadStored(0x3B)).data);
  ASSERT_EQ(soft.size(), 9u);
  for (int i = 0; i < 9; ++i) EXPECT_EQ(soft[i], static_cast<float>(kSoftIron[i]));

  const Answer t = Send(device.get(), mip::ReadStored(0x33));
  ASSERT_EQ(t.code, 0);
  ASSERT_EQ(Floats(t.data).size(), 9u);
  for (int i = 0; i < 9; ++i) EXPECT_EQ(Floats(t.data)[i], static_cast<float>(dcm[i]));

  // The output, by the device's convention written out here (not through the re-expression both
  // the emulator and turncald use): mag M S (raw - h), accel M (raw - bias), gyro M raw, from
  // samples that carried nothing.
  Sample s;
  s.mag = Eigen::Vector3d(0.25, -0.02, 0.41);
  s.acc_mps2 = Eigen::Vector3d(0.1, -0.2, 9.8);
  s.gyr_radps = Eigen::Vector3d(0.01, 0.02, 0.03);
  const Sample raw = s;
  device->ApplyStored(&s);
  // The values as the device holds them: the floats it reads back. (Rounding the constants here
  // with static_cast<float> instead came out unrounded in two of three elements when GCC 12.2
  // compiled this test at -O3: 0.0123 instead of 0.012299999594688416.)
  const std::vector<float> bias = Floats(Send(device.get(), mip::ReadStored(0x37)).data);
  const std::vector<float> transform = Floats(t.data);
  ASSERT_EQ(bias.size(), 3u);
  Eigen::Matrix3d S, M;
  Eigen::Vector3d hi, ab;
  for (int i = 0; i < 9; ++i) {
    S(i / 3, i % 3) = soft[static_cast<std::size_t>(i)];
    M(i / 3, i % 3) = transform[static_cast<std::size_t>(i)];
  }
  for (int i = 0; i < 3; ++i) {
    hi[i] = hard[static_cast<std::size_t>(i)];
    ab[i] = bias[static_cast<std::size_t>(i)];
  }
  // Equal up to the rounding of two 3x3 products and a difference in double (the emulator may
  // order the operations otherwise): each stage's error is at most gamma_3 = 3u/(1-3u) of
  // |M| |S| |v| (Higham, Accuracy and Stability, 3.5); 16 u bounds the sum of both orders' with
  // room.
  const double u = std::numeric_limits<double>::epsilon();
  const Eigen::Vector3d mag_in = *raw.mag - hi;
  const Eigen::Vector3d acc_in = *raw.acc_mps2 - ab * kStandardGravity_mps2;
  EXPECT_LT((*s.mag - M * S * mag_in).norm(), 16 * u * M.norm() * S.norm() * mag_in.norm());
  EXPECT_LT((*s.acc_mps2 - M * acc_in).norm(), 16 * u * M.norm() * acc_in.norm());
  // The gyro bias is still zero.
  EXPECT_LT((*s.gyr_radps - M * *raw.gyr_radps).norm(), 16 * u * M.norm() * raw.gyr_radps->norm());
}

TEST_F(MipStorage, SavedValuesSurviveARestartAndLoadAndDefaultWork) {
  EmulatedIdentity id = WithMagnetometerCommands();
  id.mip_nonvolatile_path = (dir_ / "SIM0001.nvm.json").string();
  {
    auto device = DeviceEmulator::Make(drivers::Protocol::kMip, id, 100);
    ASSERT_EQ(Send(device.get(), mip::WriteStored(0x3A, kHardIron)).code, 0);
    ASSERT_EQ(Send(device.get(), mip::WriteStored(0x37, kAccelBias)).code, 0);
    // Only the hard iron is saved; the accel bias written is lost at the restart.
    ASSERT_EQ(Send(device.get(), mip::StoredFunction(0x3A, 3)).code, 0);
    EXPECT_TRUE(std::filesystem::exists(id.mip_nonvolatile_path));
  }
  auto device = DeviceEmulator::Make(drivers::Protocol::kMip, id, 100);
  EXPECT_TRUE(device->storage_error().empty()) << device->storage_error();
  ASSERT_TRUE(device->mip_stored());
  const auto after = *device->mip_stored();
  for (int i = 0; i < 3; ++i) {
    EXPECT_EQ((*after.hard_iron)[i], static_cast<float>(kHardIron[i]));
    EXPECT_EQ((*after.accel_bias)[i], 0.0);
  }
  Sample s;
  s.mag = Eigen::Vector3d(0.25, -0.02, 0.41);
  device->ApplyStored(&s);
  EXPECT_NEAR(s.mag->x(), 0.25 - static_cast<float>(kHardIron[0]), 1e-15);

  // Default: the factory values in use (the startup values unchanged); load: the startup values.
  ASSERT_EQ(Send(device.get(), mip::StoredFunction(0x3A, 5)).code, 0);
  EXPECT_EQ(*device->mip_stored()->hard_iron, Eigen::Vector3d::Zero());
  EXPECT_EQ((*device->mip_nonvolatile()->hard_iron)[1], static_cast<float>(kHardIron[1]));
  ASSERT_EQ(Send(device.get(), mip::StoredFunction(0x3A, 4)).code, 0);
  EXPECT_EQ((*device->mip_stored()->hard_iron)[1], static_cast<float>(kHardIron[1]));

  // A device reset (0x01 0x7E) powers up with the startup values.
  ASSERT_EQ(Send(device.get(), mip::WriteStored(0x3A, std::vector<double>{1, 2, 3})).code, 0);
  device->OnHostBytes(mip::Packet(0x01, std::vector<mip::Field>{{0x7E, {}}}));
  EXPECT_EQ((*device->mip_stored()->hard_iron)[2], static_cast<float>(kHardIron[2]));
}

TEST_F(MipStorage, AStorageThatCannotBeWrittenRefusesTheSaveAndACorruptOneIsReported) {
  EmulatedIdentity id = WithMagnetometerCommands();
  id.mip_nonvolatile_path = (dir_ / "missing-folder" / "SIM0001.nvm.json").string();
  auto device = DeviceEmulator::Make(drivers::Protocol::kMip, id, 100);
  ASSERT_EQ(Send(device.get(), mip::WriteStored(0x3A, kHardIron)).code, 0);
  EXPECT_EQ(Send(device.get(), mip::StoredFunction(0x3A, 3)).code, 4);  // NACK "failed"
  EXPECT_FALSE(device->storage_error().empty());
  EXPECT_EQ(*device->mip_nonvolatile()->hard_iron, Eigen::Vector3d::Zero());  // nothing saved

  id.mip_nonvolatile_path = (dir_ / "corrupt.nvm.json").string();
  std::ofstream(id.mip_nonvolatile_path) << "{\"hard_iron_gauss\": [1, 2]}";
  auto corrupt = DeviceEmulator::Make(drivers::Protocol::kMip, id, 100);
  EXPECT_NE(corrupt->storage_error().find("3 (or 3 x 3) finite numbers"), std::string::npos)
      << corrupt->storage_error();
  EXPECT_EQ(*corrupt->mip_stored()->hard_iron, Eigen::Vector3d::Zero());  // the power-up values
}

TEST(MipStoredOutput, ValuesTheSamplesAlreadyCarryAreRecoveredBeforeTheNewOnesApply) {
  StoredCalibration carried = MipFactoryDefaults(WithMagnetometerCommands().mip_stored);
  carried.hard_iron = Eigen::Vector3d(0.01, 0.02, 0.03);
  carried.soft_iron = Eigen::Vector3d(1.1, 0.9, 1.0).asDiagonal();
  carried.accel_bias = Eigen::Vector3d(0.001, 0, 0);
  const Eigen::Vector3d raw_mag(0.3, 0.1, -0.4);
  Sample s;
  s.mag = *carried.soft_iron * (raw_mag - *carried.hard_iron);
  s.acc_mps2 = Eigen::Vector3d(0, 0, 9.8);
  StoredCalibration now = carried;
  now.hard_iron = Eigen::Vector3d(-0.01, 0, 0.05);
  now.soft_iron = Eigen::Matrix3d::Identity();
  now.accel_bias = Eigen::Vector3d::Zero();
  drivers::mip::ReexpressMipOutput(carried, now, &s);
  EXPECT_LT((*s.mag - (raw_mag - *now.hard_iron)).norm(), 1e-15);
  EXPECT_NEAR(s.acc_mps2->x(), 0.001 * kStandardGravity_mps2, 1e-15);
  // The same values: the sample is left bit for bit.
  Sample same;
  same.mag = Eigen::Vector3d(0.1 / 3, 0.2, 0.3);
  const Eigen::Vector3d before = *same.mag;
  drivers::mip::ReexpressMipOutput(carried, carried, &same);
  EXPECT_EQ(*same.mag, before);
}

}  // namespace
}  // namespace turncal::sim
