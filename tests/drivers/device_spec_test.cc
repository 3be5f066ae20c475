#include "drivers/device_spec.h"

#include <gtest/gtest.h>

namespace turncal::drivers {
namespace {

TEST(DeviceSpec, ParsesPathWithBaud) {
  std::string error;
  auto spec = ParseDeviceSpec("imu1=mip:/dev/ttyUSB0@921600", &error);
  ASSERT_TRUE(spec) << error;
  EXPECT_EQ(spec->name, "imu1");
  EXPECT_EQ(spec->protocol, Protocol::kMip);
  EXPECT_EQ(spec->port, "/dev/ttyUSB0");
  EXPECT_EQ(spec->baud, 921600);
}

TEST(DeviceSpec, ParsesTcpAndReplayPortsWithDefaultBaud) {
  std::string error;
  auto tcp = ParseDeviceSpec("x=xbus-legacy:tcp://127.0.0.1:4001", &error);
  ASSERT_TRUE(tcp) << error;
  EXPECT_EQ(tcp->protocol, Protocol::kXbusLegacy);
  EXPECT_EQ(tcp->port, "tcp://127.0.0.1:4001");
  EXPECT_EQ(tcp->baud, 115200);
  auto replay = ParseDeviceSpec("g=gx2:replay:session.tcap", &error);
  ASSERT_TRUE(replay) << error;
  EXPECT_EQ(replay->port, "replay:session.tcap");
}

TEST(DeviceSpec, RejectsMalformedSpecsWithAReason) {
  for (const char* bad :
       {"mip:/dev/ttyUSB0", "=mip:/dev/x", "a b=mip:/dev/x", "imu=foo:/dev/x", "imu=mip",
        "imu=mip:", "imu=mip:/dev/x@fast", "imu=mip:/dev/x@12", "imu=mip:@115200"}) {
    std::string error;
    EXPECT_FALSE(ParseDeviceSpec(bad, &error)) << bad;
    EXPECT_NE(error.find("NAME=PROTOCOL:PORT"), std::string::npos) << error;
  }
}

}  // namespace
}  // namespace turncal::drivers
