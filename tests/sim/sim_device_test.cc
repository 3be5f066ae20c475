// The device emulator behind `turncal sim --live` (sim/device.h) against the real
// configuration dialogues: an in-memory link hands what the dialogue writes to the emulator and
// queues its replies, with sample frames interleaved whenever the emulator says it streams.
#include "sim/device.h"

#include <gtest/gtest.h>

#include <deque>
#include <functional>

#include "drivers/bytes.h"
#include "drivers/mip/mip_dialogue.h"
#include "drivers/mip/mip_encoder.h"
#include "drivers/xbus/xbus_dialogue.h"
#include "drivers/xbus/xbus_encoder.h"
#include "sim/capture.h"
#include "tests/support/virtual_link.h"

namespace turncal::sim {
namespace {

using Bytes = std::vector<std::uint8_t>;
using drivers::Protocol;
namespace mip = drivers::mip;
namespace xbus = drivers::xbus;

Sample StreamSample(std::uint32_t counter) {
  Sample s;
  s.t_device_s = 10.0 + 0.01 * counter;
  s.counter = counter;
  s.acc_mps2 = Eigen::Vector3d(0.1, -0.2, 9.8);
  s.gyr_radps = Eigen::Vector3d(0.001, 0.002, -0.003);
  s.mag = Eigen::Vector3d(0.2, 0.0, 0.4);
  s.temp_c = 25.0;
  return s;
}

// A sample frame as the simulator streams it for `protocol`.
Bytes SampleFrame(Protocol protocol, std::uint32_t counter) {
  Sample s = StreamSample(counter);
  switch (protocol) {
    case Protocol::kMip:
      s.counter.reset();
      return mip::SensorPacket(s);
    case Protocol::kXbus:
      return xbus::MtData2(s);
    case Protocol::kXbusLegacy:
      return xbus::MtData(s, kSimXbusLegacyLayout);
    case Protocol::kGx2:
      break;
  }
  return {};
}

// The host's link to an emulated device, on a virtual clock. Each write goes to the emulator
// (whole, or one byte at a time); while the emulator streams, sample frames are already on their
// way before its reply and keep coming when the host waits.
class EmulatorLink : public testing_support::VirtualClockLink {
 public:
  EmulatorLink(DeviceEmulator* device, Protocol protocol)
      : VirtualClockLink(37), device_(device), protocol_(protocol) {}

  bool byte_at_a_time = false;
  int corrupt_write = 0;  // 1-based index of the write whose last byte is flipped; 0: none
  int writes = 0;
  int frames_streamed = 0;
  // (the command's first bytes, streaming() after the emulator saw it), per write.
  std::vector<std::pair<Bytes, bool>> log;

  bool Write(std::span<const std::uint8_t> bytes, std::string*) override {
    ++writes;
    Bytes sent(bytes.begin(), bytes.end());
    if (writes == corrupt_write) sent.back() ^= 0x01;
    for (int i = 0; i < 3 && device_->streaming(); ++i) Stream();
    if (byte_at_a_time) {
      for (std::uint8_t b : sent) Queue(device_->OnHostBytes(std::span<const std::uint8_t>(&b, 1)));
    } else {
      Queue(device_->OnHostBytes(sent));
    }
    log.emplace_back(Bytes(sent.begin(), sent.begin() + std::min<std::size_t>(6, sent.size())),
                     device_->streaming());
    return true;
  }

 protected:
  bool StreamWhileIdle() override {
    if (!device_->streaming()) return false;
    Stream();
    return true;
  }

 private:
  void Stream() { Queue(SampleFrame(protocol_, static_cast<std::uint32_t>(frames_streamed++))); }

  DeviceEmulator* device_;
  Protocol protocol_;
};

// Short timeouts: the clock is virtual anyway, this keeps the retries quick.
const drivers::ExchangeOptions kOptions{std::chrono::milliseconds(50), 3};

bool IsMipCommand(const Bytes& head, std::uint8_t set, std::uint8_t desc) {
  return head.size() >= 6 && head[2] == set && head[5] == desc;
}

// --------------------------------------------------------------------------------------------
// MIP

TEST(MipEmulator, ConfigureSucceedsAndReportsTheIdentity) {
  EmulatedIdentity id;
  id.serial = "SIM0042";
  // A device without the magnetometer's stored-calibration commands (they answer NACK 1).
  id.mip_stored.hard_iron.reset();
  id.mip_stored.soft_iron.reset();
  auto device = DeviceEmulator::Make(Protocol::kMip, id, 500.0);
  ASSERT_TRUE(device);
  EXPECT_EQ(device->protocol(), Protocol::kMip);
  EXPECT_TRUE(device->streaming());  // at power-up
  EXPECT_FALSE(device->requested_rate_hz());
  EmulatorLink link(device.get(), Protocol::kMip);
  mip::Dialogue dialogue(&link, kOptions);
  std::string error;
  const auto c = dialogue.Configure(500.0, &error);
  ASSERT_TRUE(c) << error;
  EXPECT_EQ(c->info.firmware, 1234);
  EXPECT_EQ(c->info.model_name, "3DM-GX5-25 sim");
  EXPECT_EQ(c->info.model_number, "6251-4220");
  EXPECT_EQ(c->info.serial, "SIM0042");
  EXPECT_EQ(c->info.lot, "sim");
  EXPECT_EQ(c->info.options, "");
  EXPECT_EQ(c->base_rate_hz, 1000);
  EXPECT_EQ(c->decimation, 2);
  ASSERT_TRUE(c->stored.accel_bias);
  ASSERT_TRUE(c->stored.gyro_bias);
  EXPECT_EQ(*c->stored.accel_bias, Eigen::Vector3d::Zero());
  EXPECT_EQ(*c->stored.gyro_bias, Eigen::Vector3d::Zero());
  EXPECT_FALSE(c->stored.hard_iron);  // NACK 1: this identity has no such command
  EXPECT_FALSE(c->stored.soft_iron);
  EXPECT_TRUE(device->streaming());
  ASSERT_TRUE(device->requested_rate_hz());
  EXPECT_DOUBLE_EQ(*device->requested_rate_hz(), 500.0);
  EXPECT_EQ(link.writes, 11);  // every command answered at the first attempt
  EXPECT_EQ(device->counters().commands, 11u);
  EXPECT_EQ(device->counters().unknown_commands, 2u);  // hard and soft iron
  EXPECT_EQ(device->counters().bad_frames, 0u);
  EXPECT_EQ(device->counters().ignored_bytes, 0u);
}

TEST(MipEmulator, DoesNotStreamBetweenIdleAndResume) {
  auto device = DeviceEmulator::Make(Protocol::kMip, {}, 100.0);
  EmulatorLink link(device.get(), Protocol::kMip);
  mip::Dialogue dialogue(&link, kOptions);
  std::string error;
  ASSERT_TRUE(dialogue.Configure(100.0, &error)) << error;
  ASSERT_EQ(link.log.size(), 11u);
  EXPECT_TRUE(IsMipCommand(link.log.front().first, 0x01, 0x02));
  EXPECT_TRUE(IsMipCommand(link.log.back().first, 0x01, 0x06));
  for (std::size_t i = 0; i + 1 < link.log.size(); ++i) {
    EXPECT_FALSE(link.log[i].second) << "streaming after command " << i;
  }
  EXPECT_TRUE(link.log.back().second);  // after resume
  // Only the frames before set-to-idle's reply and after resume were streamed.
  const int before = link.frames_streamed;
  Bytes buffer(64);
  std::string read_error;
  EXPECT_GT(link.Read(buffer, std::chrono::milliseconds(1), &read_error), 0);
  EXPECT_GT(link.frames_streamed, before);

  // Idle again: no more frames.
  ASSERT_TRUE(dialogue.SetToIdle(&error)) << error;
  EXPECT_FALSE(device->streaming());
  // The sensor stream disabled while running also stops the frames.
  ASSERT_TRUE(dialogue.Resume(&error)) << error;
  EXPECT_TRUE(device->streaming());
  ASSERT_TRUE(dialogue.EnableStream(0x80, false, &error)) << error;
  EXPECT_FALSE(device->streaming());
  ASSERT_TRUE(dialogue.EnableStream(0x80, true, &error)) << error;
  EXPECT_TRUE(device->streaming());
}

TEST(MipEmulator, AnswersCommandsDeliveredOneByteAtATime) {
  auto device = DeviceEmulator::Make(Protocol::kMip, {}, 100.0);
  EmulatorLink link(device.get(), Protocol::kMip);
  link.byte_at_a_time = true;
  mip::Dialogue dialogue(&link, kOptions);
  std::string error;
  const auto c = dialogue.Configure(100.0, &error);
  ASSERT_TRUE(c) << error;
  EXPECT_EQ(c->info.serial, "SIM0001");
  EXPECT_EQ(c->decimation, 10);
  EXPECT_EQ(link.writes, 11);
  EXPECT_EQ(device->counters().commands, 11u);
  EXPECT_EQ(device->counters().bad_frames, 0u);
}

TEST(MipEmulator, ACorruptedCommandIsCountedAndNotAnsweredAndTheRetrySucceeds) {
  auto device = DeviceEmulator::Make(Protocol::kMip, {}, 100.0);
  EmulatorLink link(device.get(), Protocol::kMip);
  link.corrupt_write = 3;  // get IMU base rate
  mip::Dialogue dialogue(&link, kOptions);
  std::string error;
  const auto c = dialogue.Configure(100.0, &error);
  ASSERT_TRUE(c) << error;
  EXPECT_EQ(c->base_rate_hz, 1000);
  EXPECT_EQ(link.writes, 12);  // the base rate request was sent twice
  EXPECT_TRUE(IsMipCommand(link.log[2].first, 0x0C, 0x06));
  EXPECT_TRUE(IsMipCommand(link.log[3].first, 0x0C, 0x06));
  EXPECT_EQ(device->counters().bad_frames, 1u);
  EXPECT_EQ(device->counters().commands, 11u);
  EXPECT_EQ(device->counters().ignored_bytes, 8u);  // the corrupted command's bytes
}

TEST(MipEmulator, ACorruptedCommandWhileStreamingIsRetriedToo) {
  auto device = DeviceEmulator::Make(Protocol::kMip, {}, 100.0);
  EmulatorLink link(device.get(), Protocol::kMip);
  link.corrupt_write = 1;  // the first set to idle: the device keeps streaming
  mip::Dialogue dialogue(&link, kOptions);
  std::string error;
  ASSERT_TRUE(dialogue.Configure(100.0, &error)) << error;
  EXPECT_EQ(link.writes, 12);
  EXPECT_TRUE(link.log[0].second);  // still streaming after the corrupted set to idle
  EXPECT_FALSE(link.log[1].second);
  EXPECT_EQ(device->counters().bad_frames, 1u);
}

TEST(MipEmulator, AnUnknownCommandGetsNack1) {
  auto device = DeviceEmulator::Make(Protocol::kMip, {}, 100.0);
  const mip::Field unknown{0x7F, {0x01}};
  EXPECT_EQ(device->OnHostBytes(mip::Packet(0x0C, {&unknown, 1})), mip::Reply(0x0C, 0x7F, 1));
  const mip::Field other_set{0x01, {}};
  EXPECT_EQ(device->OnHostBytes(mip::Packet(0x0D, {&other_set, 1})), mip::Reply(0x0D, 0x01, 1));
  EXPECT_EQ(device->counters().commands, 2u);
  EXPECT_EQ(device->counters().unknown_commands, 2u);
  // The ping the protocol manual gives, and its ACK.
  EXPECT_EQ(device->OnHostBytes(Bytes{0x75, 0x65, 0x01, 0x02, 0x02, 0x01, 0xE0, 0xC6}),
            (Bytes{0x75, 0x65, 0x01, 0x04, 0x04, 0xF1, 0x01, 0x00, 0xD5, 0x6A}));
}

TEST(MipEmulator, ABadParameterGetsNack3ThroughTheDialogue) {
  auto device = DeviceEmulator::Make(Protocol::kMip, {}, 100.0);
  EmulatorLink link(device.get(), Protocol::kMip);
  mip::Dialogue dialogue(&link, kOptions);
  std::string error;
  const std::pair<std::uint8_t, std::uint16_t> zero_decimation[] = {{0x04, 0}};
  EXPECT_FALSE(dialogue.SetImuMessageFormat(zero_decimation, &error));
  EXPECT_NE(error.find("bad parameter"), std::string::npos) << error;
  const std::pair<std::uint8_t, std::uint16_t> unknown_descriptor[] = {{0x42, 1}};
  EXPECT_FALSE(dialogue.SetImuMessageFormat(unknown_descriptor, &error));
  EXPECT_NE(error.find("bad parameter"), std::string::npos) << error;
  EXPECT_EQ(device->counters().unknown_commands, 0u);
}

TEST(MipEmulator, SkipsGarbageAndSplitsAndJoinsCommands) {
  auto device = DeviceEmulator::Make(Protocol::kMip, {}, 100.0);
  const Bytes ping = mip::Ping(), idle = mip::SetToIdle(), resume = mip::Resume();
  // Garbage (with a false sync byte) before a ping split over three chunks.
  EXPECT_TRUE(device->OnHostBytes(Bytes{0x00, 0x75, 0x12, 0xFF}).empty());
  EXPECT_TRUE(device->OnHostBytes(std::span(ping).first(3)).empty());
  EXPECT_TRUE(device->OnHostBytes(std::span(ping).subspan(3, 2)).empty());
  EXPECT_EQ(device->OnHostBytes(std::span(ping).subspan(5)), mip::Reply(0x01, 0x01, 0));
  EXPECT_EQ(device->counters().ignored_bytes, 4u);
  // Two commands in one chunk: two replies, in order.
  Bytes both = idle;
  both.insert(both.end(), resume.begin(), resume.end());
  Bytes expected = mip::Reply(0x01, 0x02, 0);
  const Bytes resumed = mip::Reply(0x01, 0x06, 0);
  expected.insert(expected.end(), resumed.begin(), resumed.end());
  EXPECT_EQ(device->OnHostBytes(both), expected);
  EXPECT_TRUE(device->streaming());
  EXPECT_EQ(device->counters().commands, 3u);
  EXPECT_EQ(device->counters().bad_frames, 0u);
}

TEST(MipEmulator, DropsAStaleHalfCommandAfterTheTimeout) {
  auto device = DeviceEmulator::Make(Protocol::kMip, {}, 100.0);
  std::int64_t now = 0;
  device->set_clock([&now] { return now; });
  const Bytes ping = mip::Ping();
  // A header whose length byte would swallow the next command (0x75 = 117 bytes).
  EXPECT_TRUE(device->OnHostBytes(Bytes{0x75, 0x65, 0x01}).empty());
  now += 100'000'000;  // 100 ms later, past the 34 ms timeout
  EXPECT_EQ(device->OnHostBytes(ping), mip::Reply(0x01, 0x01, 0));
  EXPECT_EQ(device->counters().bad_frames, 1u);
  EXPECT_EQ(device->counters().ignored_bytes, 3u);
  // Without the wait the half command holds the next one back.
  EXPECT_TRUE(device->OnHostBytes(Bytes{0x75, 0x65, 0x01}).empty());
  EXPECT_TRUE(device->OnHostBytes(ping).empty());
}

TEST(MipEmulator, ReportsTheStoredCalibrationOfItsIdentity) {
  EmulatedIdentity id;
  id.mip_stored.accel_bias = Eigen::Vector3d(0.001, -0.002, 0.003);
  id.mip_stored.hard_iron = Eigen::Vector3d(0.1, 0.2, -0.3);
  Eigen::Matrix3d soft;
  soft << 1.1, 0.01, 0.02, 0.01, 0.9, 0.03, 0.02, 0.03, 1.0;
  id.mip_stored.soft_iron = soft;
  id.mip_stored.gyro_bias.reset();
  auto device = DeviceEmulator::Make(Protocol::kMip, id, 100.0);
  EmulatorLink link(device.get(), Protocol::kMip);
  mip::Dialogue dialogue(&link, kOptions);
  std::string error;
  const auto c = dialogue.Configure(100.0, &error);
  ASSERT_TRUE(c) << error;
  ASSERT_TRUE(c->stored.accel_bias);
  EXPECT_NEAR(c->stored.accel_bias->y(), -0.002, 1e-7);
  EXPECT_FALSE(c->stored.gyro_bias);
  ASSERT_TRUE(c->stored.hard_iron);
  EXPECT_NEAR(c->stored.hard_iron->z(), -0.3, 1e-7);
  ASSERT_TRUE(c->stored.soft_iron);
  EXPECT_NEAR((*c->stored.soft_iron)(1, 2), 0.03, 1e-7);
  EXPECT_NEAR((*c->stored.soft_iron)(2, 1), 0.03, 1e-7);
  EXPECT_NEAR((*c->stored.soft_iron)(0, 0), 1.1, 1e-7);
  EXPECT_EQ(device->counters().unknown_commands, 1u);  // gyro bias
}

TEST(MipEmulator, TheBaseRateMakesTheDecimationGiveTheStreamRate) {
  for (double rate : {100.0, 125.0, 200.0, 250.0, 300.0, 500.0, 1000.0, 2000.0, 1000.0 / 3}) {
    auto device = DeviceEmulator::Make(Protocol::kMip, {}, rate);
    EmulatorLink link(device.get(), Protocol::kMip);
    mip::Dialogue dialogue(&link, kOptions);
    std::string error;
    const auto c = dialogue.Configure(rate, &error);
    ASSERT_TRUE(c) << rate << ": " << error;
    EXPECT_EQ(c->base_rate_hz, MipBaseRate(rate)) << rate;
    EXPECT_GE(c->base_rate_hz, 1000) << rate;
    EXPECT_NEAR(static_cast<double>(c->base_rate_hz) / c->decimation, rate, 0.01 * rate) << rate;
    ASSERT_TRUE(device->requested_rate_hz());
    EXPECT_NEAR(*device->requested_rate_hz(), rate, 0.01 * rate) << rate;
  }
  EXPECT_EQ(MipBaseRate(500), 1000);
  EXPECT_EQ(MipBaseRate(300), 1200);
  EXPECT_EQ(MipBaseRate(2000), 2000);
  EXPECT_EQ(MipBaseRate(0), 1000);
}

// --------------------------------------------------------------------------------------------
// Xbus

const xbus::OutputConfiguration kWanted = {{xbus::kPacketCounter, 0xFFFF},
                                           {xbus::kSampleTimeFine, 0xFFFF},
                                           {xbus::kAcceleration, 100},
                                           {xbus::kRateOfTurn, 100},
                                           {xbus::kMagneticField, 100}};

TEST(XbusEmulator, ConfigureSucceedsAndReportsTheIdentity) {
  EmulatedIdentity id;
  id.xbus_device_id = 0x03700042;
  id.xbus_firmware = {1, 8, 2};
  auto device = DeviceEmulator::Make(Protocol::kXbus, id, 100.0);
  ASSERT_TRUE(device);
  EXPECT_EQ(device->protocol(), Protocol::kXbus);
  EXPECT_TRUE(device->streaming());
  EmulatorLink link(device.get(), Protocol::kXbus);
  xbus::Dialogue dialogue(&link, kOptions);
  std::string error;
  const auto got = dialogue.Configure(kWanted, &error);
  ASSERT_TRUE(got) << error;
  EXPECT_EQ(got->device_id, 0x03700042u);
  EXPECT_EQ(got->product_code, "MTi-3-sim");
  EXPECT_EQ(got->firmware, "1.8.2");
  EXPECT_TRUE(device->streaming());
  ASSERT_TRUE(device->requested_rate_hz());
  EXPECT_DOUBLE_EQ(*device->requested_rate_hz(), 100.0);
  EXPECT_EQ(link.writes, 6);  // GoToConfig, DID, product code, firmware, output, measurement
  EXPECT_EQ(device->counters().commands, 6u);
  EXPECT_EQ(device->counters().unknown_commands, 0u);
  EXPECT_EQ(device->counters().bad_frames, 0u);
  // The configuration can be read back (SetOutputConfiguration without data).
  Bytes applied;
  for (const auto& [xdi, rate] : kWanted) {
    drivers::PutU16(&applied, xdi);
    drivers::PutU16(&applied, rate);
  }
  EXPECT_EQ(device->OnHostBytes(xbus::Message(xbus::kSetOutputConfiguration)),
            xbus::Message(xbus::kOutputConfiguration, applied));
}

TEST(XbusEmulator, DoesNotStreamBetweenConfigAndMeasurement) {
  auto device = DeviceEmulator::Make(Protocol::kXbus, {}, 100.0);
  EmulatorLink link(device.get(), Protocol::kXbus);
  xbus::Dialogue dialogue(&link, kOptions);
  std::string error;
  ASSERT_TRUE(dialogue.Configure(kWanted, &error)) << error;
  ASSERT_EQ(link.log.size(), 6u);
  EXPECT_EQ(link.log.front().first[2], xbus::kGoToConfig);
  EXPECT_EQ(link.log.back().first[2], xbus::kGoToMeasurement);
  for (std::size_t i = 0; i + 1 < link.log.size(); ++i) {
    EXPECT_FALSE(link.log[i].second) << "streaming after message " << i;
  }
  EXPECT_TRUE(link.log.back().second);
  ASSERT_TRUE(dialogue.GoToConfig(&error)) << error;
  EXPECT_FALSE(device->streaming());
  // WakeUpAck keeps a device in config state; Reset returns it to measurement.
  EXPECT_TRUE(device->OnHostBytes(xbus::Message(xbus::kWakeUpAck)).empty());
  EXPECT_FALSE(device->streaming());
  EXPECT_EQ(device->OnHostBytes(xbus::Message(xbus::kReset)), xbus::Message(xbus::kReset + 1));
  EXPECT_TRUE(device->streaming());
}

TEST(XbusEmulator, AnswersMessagesDeliveredOneByteAtATime) {
  auto device = DeviceEmulator::Make(Protocol::kXbus, {}, 100.0);
  EmulatorLink link(device.get(), Protocol::kXbus);
  link.byte_at_a_time = true;
  xbus::Dialogue dialogue(&link, kOptions);
  std::string error;
  const auto got = dialogue.Configure(kWanted, &error);
  ASSERT_TRUE(got) << error;
  EXPECT_EQ(got->device_id, 0x03700001u);
  EXPECT_EQ(link.writes, 6);
  EXPECT_EQ(device->counters().commands, 6u);
  EXPECT_EQ(device->counters().bad_frames, 0u);
}

TEST(XbusEmulator, ACorruptedMessageIsCountedAndNotAnsweredAndTheRetrySucceeds) {
  for (int corrupt : {1, 5}) {  // GoToConfig while streaming; SetOutputConfiguration in config
    auto device = DeviceEmulator::Make(Protocol::kXbus, {}, 100.0);
    EmulatorLink link(device.get(), Protocol::kXbus);
    link.corrupt_write = corrupt;
    xbus::Dialogue dialogue(&link, kOptions);
    std::string error;
    ASSERT_TRUE(dialogue.Configure(kWanted, &error)) << corrupt << ": " << error;
    EXPECT_EQ(link.writes, 7) << corrupt;
    EXPECT_EQ(link.log[corrupt - 1].first[2], link.log[corrupt].first[2]) << corrupt;
    EXPECT_EQ(device->counters().bad_frames, 1u) << corrupt;
    EXPECT_EQ(device->counters().commands, 6u) << corrupt;
    EXPECT_TRUE(device->streaming());
  }
}

TEST(XbusEmulator, AnUnknownMessageGetsAnError) {
  auto device = DeviceEmulator::Make(Protocol::kXbus, {}, 100.0);
  EXPECT_EQ(device->OnHostBytes(xbus::Message(0x0C)), xbus::Message(xbus::kError, Bytes{0x04}));
  EXPECT_EQ(device->counters().unknown_commands, 1u);
  // An MTData2 device has no legacy output mode: the dialogue reports the error.
  EmulatorLink link(device.get(), Protocol::kXbus);
  xbus::Dialogue dialogue(&link, kOptions);
  std::string error;
  ASSERT_TRUE(dialogue.GoToConfig(&error)) << error;
  EXPECT_FALSE(dialogue.ReadLegacyLayout(&error));
  EXPECT_NE(error.find("error 0x04 (invalid message)"), std::string::npos) << error;
  EXPECT_EQ(device->counters().unknown_commands, 2u);
  // A SetOutputConfiguration whose data is not whole (XDI, rate) pairs: invalid parameter.
  EXPECT_EQ(device->OnHostBytes(xbus::Message(xbus::kSetOutputConfiguration, Bytes{0x40, 0x20, 0})),
            xbus::Message(xbus::kError, Bytes{0x21}));
}

TEST(XbusLegacyEmulator, ReportsTheLayoutTheSimulatorStreams) {
  auto device = DeviceEmulator::Make(Protocol::kXbusLegacy, {}, 100.0);
  ASSERT_TRUE(device);
  EXPECT_EQ(device->protocol(), Protocol::kXbusLegacy);
  EmulatorLink link(device.get(), Protocol::kXbusLegacy);
  xbus::Dialogue dialogue(&link, kOptions);
  std::string error;
  ASSERT_TRUE(dialogue.GoToConfig(&error)) << error;
  EXPECT_FALSE(device->streaming());
  const auto id = dialogue.Identify(&error);
  ASSERT_TRUE(id) << error;
  EXPECT_EQ(id->device_id, 0x03700001u);
  EXPECT_EQ(id->product_code, "MTi-3-sim");
  const auto layout = dialogue.ReadLegacyLayout(&error);
  ASSERT_TRUE(layout) << error;
  EXPECT_EQ(layout->output_mode, kSimXbusLegacyLayout.output_mode);
  EXPECT_EQ(layout->output_settings, kSimXbusLegacyLayout.output_settings);
  EXPECT_EQ(layout->PayloadSize(nullptr), 42u);
  EXPECT_FALSE(device->streaming());
  ASSERT_TRUE(dialogue.GoToMeasurement(&error)) << error;
  EXPECT_TRUE(device->streaming());
  EXPECT_EQ(device->counters().unknown_commands, 0u);

  // The layout read from the device decodes what the simulator streams.
  struct Samples : drivers::DecoderSink {
    void OnFrame(const drivers::FrameView&) override {}
    void OnSample(const Sample& s) override { got.push_back(s); }
    std::vector<Sample> got;
  } sink;
  drivers::XbusDecoder decoder("imu", &sink, *layout);
  decoder.Push(SampleFrame(Protocol::kXbusLegacy, 7), 0);
  ASSERT_EQ(sink.got.size(), 1u);
  EXPECT_EQ(sink.got[0].counter, 7u);
  ASSERT_TRUE(sink.got[0].acc_mps2);
  EXPECT_NEAR(sink.got[0].acc_mps2->z(), 9.8, 1e-5);
  ASSERT_TRUE(sink.got[0].temp_c);
  EXPECT_NEAR(*sink.got[0].temp_c, 25.0, 1e-5);
}

TEST(XbusLegacyEmulator, TheLayoutIsTheOneSimCaptureWrites) {
  // sim/capture.cc keeps its layout to itself; its capture header says which it used.
  SimCaptureOptions options;
  options.protocol = Protocol::kXbusLegacy;
  options.poses = {TablePose{}};
  options.session.dwell_s = 0.5;
  SimCapture capture;
  std::string error;
  ASSERT_TRUE(BuildSimCapture(options, &capture, &error)) << error;
  ASSERT_EQ(capture.header.devices.size(), 1u);
  EXPECT_EQ(capture.header.devices[0].output_mode, kSimXbusLegacyLayout.output_mode);
  EXPECT_EQ(capture.header.devices[0].output_settings, kSimXbusLegacyLayout.output_settings);
}

TEST(XbusLegacyEmulator, RefusesWhatALegacyDeviceDoesNotKnowOrCannotDo) {
  auto device = DeviceEmulator::Make(Protocol::kXbusLegacy, {}, 100.0);
  EmulatorLink link(device.get(), Protocol::kXbusLegacy);
  xbus::Dialogue dialogue(&link, kOptions);
  std::string error;
  // No MTData2 output configuration on a legacy device.
  EXPECT_FALSE(dialogue.Configure(kWanted, &error));
  EXPECT_NE(error.find("SetOutputConfiguration"), std::string::npos) << error;
  EXPECT_NE(error.find("invalid message"), std::string::npos) << error;
  EXPECT_FALSE(device->requested_rate_hz());
  // Setting the output mode it streams is acknowledged; another one is refused.
  EXPECT_EQ(device->OnHostBytes(xbus::Message(xbus::kReqOutputMode, Bytes{0x00, 0x03})),
            xbus::Message(xbus::kReqOutputMode + 1));
  EXPECT_EQ(device->OnHostBytes(xbus::Message(xbus::kReqOutputMode, Bytes{0x00, 0x02})),
            xbus::Message(xbus::kError, Bytes{0x21}));
  EXPECT_EQ(
      device->OnHostBytes(xbus::Message(xbus::kReqOutputSettings, Bytes{0x00, 0x00, 0x01, 0x01})),
      xbus::Message(xbus::kError, Bytes{0x21}));
}

// --------------------------------------------------------------------------------------------
// gx2

TEST(Gx2Emulator, StreamsAlwaysAndAnswersNothing) {
  auto device = DeviceEmulator::Make(Protocol::kGx2, {}, 100.0);
  ASSERT_TRUE(device);
  EXPECT_EQ(device->protocol(), Protocol::kGx2);
  EXPECT_TRUE(device->streaming());
  const Bytes start = {0xC4, 0xC1, 0x29, 0xCB};
  const Bytes stop = {0xFA, 0x75, 0xB4};
  EXPECT_TRUE(device->OnHostBytes(start).empty());
  EXPECT_TRUE(device->OnHostBytes(stop).empty());
  EXPECT_TRUE(device->streaming());
  EXPECT_EQ(device->counters().ignored_bytes, 7u);
  EXPECT_EQ(device->counters().commands, 0u);
  EXPECT_FALSE(device->requested_rate_hz());
}

}  // namespace
}  // namespace turncal::sim
