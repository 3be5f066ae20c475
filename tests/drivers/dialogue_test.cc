// The device dialogues against scripted devices: a virtual clock, replies interleaved with
// streaming data, a lost reply, NACKs and error messages, an unplugged device.
#include <gtest/gtest.h>

#include <deque>
#include <functional>

#include "drivers/bytes.h"
#include "drivers/mip/mip_dialogue.h"
#include "drivers/mip/mip_encoder.h"
#include "drivers/xbus/xbus_dialogue.h"
#include "drivers/xbus/xbus_encoder.h"
#include "tests/support/virtual_link.h"

namespace turncal::drivers {
namespace {

using Bytes = std::vector<std::uint8_t>;

class ScriptedLink : public testing_support::VirtualClockLink {
 public:
  ScriptedLink() : VirtualClockLink(37) {}
  std::function<Bytes(std::span<const std::uint8_t>)> on_write;  // the device's answer
  std::function<Bytes()> stream;                                 // data while streaming
  bool streaming = true;
  bool unplugged = false;
  int writes = 0;

  bool Write(std::span<const std::uint8_t> bytes, std::string* error) override {
    if (unplugged) {
      *error = "device unplugged";
      return false;
    }
    ++writes;
    // Some streaming data is already on its way before the answer.
    for (int i = 0; i < 3 && streaming; ++i) Queue(stream());
    Queue(on_write(bytes));
    return true;
  }

 protected:
  bool StreamWhileIdle() override {
    if (!streaming) return false;
    Queue(stream());
    return true;
  }
};

Bytes Floats(std::initializer_list<float> values) {
  Bytes out;
  for (float v : values) PutF32(&out, v);
  return out;
}

// A MIP device: loses its first set-to-idle reply, knows no soft-iron command.
struct MipDevice {
  ScriptedLink link;
  int idle_requests = 0;
  std::uint8_t format_code = 0;

  MipDevice() {
    link.stream = [] {
      Sample s;
      s.t_device_s = 1.0;
      s.acc_mps2 = Eigen::Vector3d(0, 0, -9.8);
      return mip::SensorPacket(s);
    };
    link.on_write = [this](std::span<const std::uint8_t> w) -> Bytes {
      const std::uint8_t set = w[2], cmd = w[5];
      if (set == 0x01 && cmd == 0x02) {
        if (++idle_requests == 1) return {};  // lost among the streaming data
        link.streaming = false;
        return mip::Reply(set, cmd, 0);
      }
      if (set == 0x01 && cmd == 0x03) {
        Bytes info;
        PutU16(&info, 1234);
        for (const char* s : {"3DM-GX5-25", "6251-4220", "6251.12345", "lot 7", "none"}) {
          std::string padded(s);
          padded.resize(16, ' ');
          info.insert(info.end(), padded.begin(), padded.end());
        }
        const mip::Field f{0x81, info};
        return mip::Reply(set, cmd, 0, std::span<const mip::Field>(&f, 1));
      }
      if (set == 0x0C && cmd == 0x06) {
        Bytes rate;
        PutU16(&rate, 1000);
        const mip::Field f{0x83, rate};
        return mip::Reply(set, cmd, 0, std::span<const mip::Field>(&f, 1));
      }
      if (set == 0x0C && cmd == 0x08) return mip::Reply(set, cmd, format_code);
      if (set == 0x0C && (cmd == 0x37 || cmd == 0x38 || cmd == 0x3A)) {
        const mip::Field f{static_cast<std::uint8_t>(cmd + 0x60),
                           Floats({0.001f, -0.002f, 0.003f})};
        return mip::Reply(set, cmd, 0, std::span<const mip::Field>(&f, 1));
      }
      if (set == 0x0C && cmd == 0x3B) return mip::Reply(set, cmd, 1);  // unknown command
      if (set == 0x0C && cmd == 0x11) return mip::Reply(set, cmd, 0);
      if (set == 0x01 && cmd == 0x06) {
        link.streaming = true;
        return mip::Reply(set, cmd, 0);
      }
      return mip::Reply(set, cmd, 1);
    };
  }
};

TEST(MipDialogue, ConfiguresAStreamingDeviceThatLosesAReply) {
  MipDevice device;
  mip::Dialogue dialogue(&device.link);
  std::string error;
  const auto c = dialogue.Configure(100.0, &error);
  ASSERT_TRUE(c) << error;
  EXPECT_EQ(device.idle_requests, 2);  // retried once
  EXPECT_EQ(c->info.firmware, 1234);
  EXPECT_EQ(c->info.model_name, "3DM-GX5-25");
  EXPECT_EQ(c->info.serial, "6251.12345");
  EXPECT_EQ(c->base_rate_hz, 1000);
  EXPECT_EQ(c->decimation, 10);
  ASSERT_TRUE(c->stored.accel_bias);
  EXPECT_NEAR(c->stored.accel_bias->y(), -0.002, 1e-7);
  EXPECT_TRUE(c->stored.hard_iron);
  EXPECT_FALSE(c->stored.soft_iron);  // the device does not know the command
  EXPECT_TRUE(device.link.streaming);
}

TEST(MipDialogue, ANackIsAnErrorWithItsMeaning) {
  MipDevice device;
  device.format_code = 3;
  mip::Dialogue dialogue(&device.link);
  std::string error;
  EXPECT_FALSE(dialogue.Configure(100.0, &error));
  EXPECT_NE(error.find("set IMU message format"), std::string::npos) << error;
  EXPECT_NE(error.find("bad parameter"), std::string::npos) << error;
}

TEST(MipDialogue, ASilentDeviceTimesOutAfterTheRetries) {
  MipDevice device;
  device.link.on_write = [](std::span<const std::uint8_t>) { return Bytes{}; };
  mip::Dialogue dialogue(&device.link, ExchangeOptions{std::chrono::milliseconds(50), 3});
  std::string error;
  EXPECT_FALSE(dialogue.SetToIdle(&error));
  EXPECT_EQ(device.link.writes, 3);
  EXPECT_NE(error.find("no reply after 3 attempt(s)"), std::string::npos) << error;
}

TEST(MipDialogue, AnUnpluggedDeviceIsAClearError) {
  MipDevice device;
  device.link.unplugged = true;
  mip::Dialogue dialogue(&device.link);
  std::string error;
  EXPECT_FALSE(dialogue.SetToIdle(&error));
  EXPECT_NE(error.find("device unplugged"), std::string::npos) << error;
}

// An Xsens device: ignores its first GoToConfig while streaming.
struct XbusDevice {
  ScriptedLink link;
  int config_requests = 0;
  std::function<Bytes(const Bytes&)> output_ack = [](const Bytes& data) {
    return xbus::Message(xbus::kOutputConfiguration, data);
  };

  XbusDevice() {
    link.stream = [] {
      Sample s;
      s.counter = 7;
      s.acc_mps2 = Eigen::Vector3d(0, 0, 9.8);
      return xbus::MtData2(s);
    };
    link.on_write = [this](std::span<const std::uint8_t> w) -> Bytes {
      const std::uint8_t mid = w[2];
      const Bytes data(w.begin() + 4, w.end() - 1);
      switch (mid) {
        case xbus::kGoToConfig:
          if (++config_requests == 1) return {};
          link.streaming = false;
          return xbus::Message(xbus::kGoToConfigAck);
        case xbus::kReqDid:
          return xbus::Message(xbus::kDeviceId, Bytes{0x03, 0x78, 0x12, 0x34});
        case xbus::kReqProductCode: {
          const std::string code = "MTi-300-2A8G4";
          return xbus::Message(xbus::kProductCode, Bytes(code.begin(), code.end()));
        }
        case xbus::kReqFwRev:
          return xbus::Message(0x13, Bytes{1, 8, 2});
        case xbus::kSetOutputConfiguration:
          return output_ack(data);
        case xbus::kReqOutputMode:
          return xbus::Message(xbus::kReqOutputMode + 1, Bytes{0x00, 0x03});
        case xbus::kReqOutputSettings:
          return xbus::Message(xbus::kReqOutputSettings + 1, Bytes{0x00, 0x00, 0x00, 0x01});
        case xbus::kGoToMeasurement:
          link.streaming = true;
          return xbus::Message(xbus::kGoToMeasurementAck);
        default:
          return xbus::Message(xbus::kError, Bytes{0x04});
      }
    };
  }
};

const xbus::OutputConfiguration kWanted = {{0x1020, 0xFFFF}, {0x4020, 100}, {0xC020, 100}};

TEST(XbusDialogue, ConfiguresAStreamingDevice) {
  XbusDevice device;
  xbus::Dialogue dialogue(&device.link);
  std::string error;
  const auto id = dialogue.Configure(kWanted, &error);
  ASSERT_TRUE(id) << error;
  EXPECT_EQ(device.config_requests, 2);
  EXPECT_EQ(id->device_id, 0x03781234u);
  EXPECT_EQ(id->product_code, "MTi-300-2A8G4");
  EXPECT_EQ(id->firmware, "1.8.2");
  EXPECT_TRUE(device.link.streaming);
}

TEST(XbusDialogue, ADataOverflowErrorIsSurfacedWithItsMeaning) {
  XbusDevice device;
  device.output_ack = [](const Bytes&) { return xbus::Message(xbus::kError, Bytes{0x29}); };
  xbus::Dialogue dialogue(&device.link);
  std::string error;
  EXPECT_FALSE(dialogue.Configure(kWanted, &error));
  EXPECT_NE(error.find("0x29"), std::string::npos) << error;
  EXPECT_NE(error.find("data overflow"), std::string::npos) << error;
}

TEST(XbusDialogue, AConfigurationTheDeviceChangedIsReported) {
  XbusDevice device;
  device.output_ack = [](const Bytes& data) {
    Bytes changed = data;
    changed[7] = 50;  // 0x4020 at 50 Hz instead of 100
    return xbus::Message(xbus::kOutputConfiguration, changed);
  };
  xbus::Dialogue dialogue(&device.link);
  std::string error;
  xbus::OutputConfiguration applied;
  ASSERT_TRUE(dialogue.GoToConfig(&error)) << error;
  EXPECT_FALSE(dialogue.SetOutputConfiguration(kWanted, &applied, &error));
  EXPECT_NE(error.find("0x4020@50"), std::string::npos) << error;
  ASSERT_EQ(applied.size(), 3u);
  EXPECT_EQ(applied[1].second, 50);
}

TEST(XbusDialogue, ReadsTheLegacyLayoutFromTheDevice) {
  XbusDevice device;
  xbus::Dialogue dialogue(&device.link);
  std::string error;
  ASSERT_TRUE(dialogue.GoToConfig(&error)) << error;
  const auto layout = dialogue.ReadLegacyLayout(&error);
  ASSERT_TRUE(layout) << error;
  EXPECT_EQ(layout->output_mode, 0x0003);
  EXPECT_EQ(layout->output_settings, 0x00000001u);
  EXPECT_EQ(layout->PayloadSize(nullptr), 42u);
}

}  // namespace
}  // namespace turncal::drivers
