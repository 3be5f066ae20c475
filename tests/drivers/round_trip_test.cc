// Encode -> decode round trips for every frame type, and the encoders against PROTOCOLS.md's
// test vectors.
#include <gtest/gtest.h>

#include "drivers/gx2/gx2_encoder.h"
#include "drivers/mip/mip_decoder.h"
#include "drivers/mip/mip_encoder.h"
#include "drivers/xbus/xbus_encoder.h"
#include "tests/drivers/decoder_test_util.h"

namespace turncal::drivers {
namespace {

using testing::CollectingSink;
using testing::Hex;

Sample Full() {
  Sample s;
  s.t_device_s = 123.4567;
  s.counter = 65535;
  s.acc_mps2 = Eigen::Vector3d(0.1234, -9.7765, 0.5);
  s.gyr_radps = Eigen::Vector3d(-0.00123, 0.0456, 1.5);
  s.mag = Eigen::Vector3d(0.25, -0.0217, 0.4004);
  s.temp_c = 31.25;
  return s;
}

void ExpectNear(const Eigen::Vector3d& a, const Eigen::Vector3d& b, double tol) {
  EXPECT_LT((a - b).cwiseAbs().maxCoeff(), tol) << a.transpose() << " vs " << b.transpose();
}

TEST(MipEncoder, CommandsEqualTheTestVectors) {
  EXPECT_EQ(mip::Ping(), Hex("75 65 01 02 02 01 E0 C6"));
  EXPECT_EQ(mip::SetToIdle(), Hex("75 65 01 02 02 02 E1 C7"));
  EXPECT_EQ(mip::Resume(), Hex("75 65 01 02 02 06 E5 CB"));
  EXPECT_EQ(mip::GetDeviceInfo(), Hex("75 65 01 02 02 03 E2 C8"));
  const std::pair<std::uint8_t, std::uint16_t> format[] = {{0x04, 10}, {0x05, 10}, {0x06, 10}};
  EXPECT_EQ(mip::ImuMessageFormat(format),
            Hex("75 65 0C 0D 0D 08 01 03 04 00 0A 05 00 0A 06 00 0A 39 7D"));
  EXPECT_EQ(mip::Reply(0x01, 0x01, 0x00), Hex("75 65 01 04 04 F1 01 00 D5 6A"));
  EXPECT_EQ(mip::Packet(0x01, {}), Hex("75 65 01 00 DB 05"));
}

TEST(MipEncoder, SensorPacketRoundTrip) {
  for (std::uint32_t flags :
       {0u, unsigned{kAccSaturated}, unsigned{kAccSaturated | kMagSaturated}}) {
    Sample in = Full();
    in.counter.reset();  // MIP has no counter
    in.flags = flags;
    CollectingSink sink;
    MipDecoder d("imu", &sink);
    d.Push(mip::SensorPacket(in), 5);
    d.Finish();
    ASSERT_EQ(sink.samples.size(), 1u);
    const Sample& out = sink.samples[0];
    EXPECT_NEAR(*out.t_device_s, *in.t_device_s, 1e-9);
    ExpectNear(*out.acc_mps2, *in.acc_mps2, 1e-5);
    ExpectNear(*out.gyr_radps, *in.gyr_radps, 1e-6);
    ExpectNear(*out.mag, *in.mag, 1e-6);
    EXPECT_NEAR(*out.temp_c, *in.temp_c, 1e-5);
    EXPECT_EQ(out.flags, flags);
  }
  for (std::uint8_t d : {0x37, 0x38, 0x3A, 0x3B}) {
    const auto cmd = mip::ReadStored(d);
    CollectingSink sink;
    MipDecoder dec("imu", &sink);
    dec.Push(cmd, 0);
    EXPECT_EQ(dec.counters().frames, 1u);
  }
  CollectingSink sink;
  MipDecoder dec("imu", &sink);
  dec.Push(mip::EnableStream(0x80, true), 0);
  dec.Push(mip::GetImuBaseRate(), 0);
  EXPECT_EQ(dec.counters().frames, 2u);
}

TEST(XbusEncoder, CommandsEqualTheTestVectors) {
  EXPECT_EQ(xbus::Message(xbus::kGoToConfig), Hex("FA FF 30 00 D1"));
  EXPECT_EQ(xbus::Message(xbus::kGoToConfigAck), Hex("FA FF 31 00 D0"));
  EXPECT_EQ(xbus::Message(xbus::kGoToMeasurement), Hex("FA FF 10 00 F1"));
  EXPECT_EQ(xbus::Message(xbus::kReqDid), Hex("FA FF 00 00 01"));
  EXPECT_EQ(xbus::Message(xbus::kWakeUpAck), Hex("FA FF 3F 00 C2"));
  EXPECT_EQ(xbus::Message(xbus::kReset), Hex("FA FF 40 00 C1"));
  EXPECT_STREQ(xbus::ErrorMeaning(0x29), "data overflow: more output than the baud rate carries");
}

TEST(XbusEncoder, MtData2RoundTripInEveryFormatAndFrame) {
  const double tolerance[4] = {1e-5, 2e-6, 1e-9, 1e-12};
  for (int format = 0; format < 4; ++format) {
    for (VectorFrame frame : {VectorFrame::kEnu, VectorFrame::kNed, VectorFrame::kNwu}) {
      Sample in = Full();
      in.flags = kGyrSaturated;
      CollectingSink sink;
      XbusDecoder d("mti", &sink);
      d.Push(xbus::MtData2(in, {format, frame}), 0);
      ASSERT_EQ(sink.samples.size(), 1u) << format;
      const Sample& out = sink.samples[0];
      EXPECT_EQ(out.counter, in.counter);
      EXPECT_NEAR(*out.t_device_s, *in.t_device_s, 1e-9);
      ExpectNear(*out.acc_mps2, *in.acc_mps2, tolerance[format] * 10);
      ExpectNear(*out.gyr_radps, *in.gyr_radps, tolerance[format]);
      ExpectNear(*out.mag, *in.mag, tolerance[format]);
      EXPECT_NEAR(*out.temp_c, *in.temp_c, tolerance[format] * 10);
      EXPECT_EQ(out.frame, frame);
      EXPECT_EQ(out.flags & kGyrSaturated, unsigned{kGyrSaturated});
    }
  }
}

TEST(XbusEncoder, PacketCounterGapsAreLostSamples) {
  CollectingSink sink;
  XbusDecoder d("mti", &sink);
  for (std::uint32_t counter : {65534u, 65535u, 0u, 3u, 4u}) {  // wraps, then 1, 2 are lost
    Sample s = Full();
    s.counter = counter;
    d.Push(xbus::MtData2(s), 0);
  }
  EXPECT_EQ(d.counters().samples, 5u);
  EXPECT_EQ(d.counters().lost_samples, 2u);
}

// A message whose counter two bit errors corrupted (the 8-bit checksum still sums to 0) is not a
// gap: the next counter continues the old sequence. A real jump is counted when the next counter
// continues from it.
TEST(XbusEncoder, CorruptedPacketCounterIsNotAGap) {
  const auto lost = [](std::initializer_list<std::uint32_t> counters) {
    CollectingSink sink;
    XbusDecoder d("mti", &sink);
    for (std::uint32_t counter : counters) {
      Sample s = Full();
      s.counter = counter;
      d.Push(xbus::MtData2(s), 0);
    }
    EXPECT_EQ(d.counters().samples, counters.size());
    return d.counters().lost_samples;
  };
  EXPECT_EQ(lost({10, 11, 11 ^ 0x4000, 13, 14}), 0u);  // bit 14 of sample 12's counter
  EXPECT_EQ(lost({10, 11, 12 ^ 0x0100, 13, 14}), 0u);  // backwards
  EXPECT_EQ(lost({10, 11, 12 ^ 0x0100, 15, 16}), 2u);  // corrupted, then 13 and 14 lost
  EXPECT_EQ(lost({10, 11, 1011, 1012, 1013}), 999u);   // a real gap
  EXPECT_EQ(lost({10, 11, 1011, 1015, 1016}), 1002u);  // a real gap, then 3 more lost
  EXPECT_EQ(lost({65535, 3, 4}), 3u);                  // across the wrap
}

TEST(XbusEncoder, ExtendedLengthAndConfigurationRoundTrip) {
  std::vector<std::pair<std::uint16_t, std::uint16_t>> outputs(32, {0x4020, 100});
  const auto set = xbus::SetOutputConfiguration(outputs);
  std::vector<std::uint8_t> big(300, 0x5A);
  const auto ext = xbus::Message(0x7F, big);
  EXPECT_EQ(ext[3], 0xFF);
  CollectingSink sink;
  XbusDecoder d("mti", &sink);
  d.Push(set, 0);
  d.Push(ext, 0);
  ASSERT_EQ(sink.frames.kind.size(), 2u);
  EXPECT_EQ(sink.frames.kind[0], xbus::kSetOutputConfiguration);
  EXPECT_EQ(XbusDecoder::Payload(sink.frames.bytes[1]).size(), 300u);
}

TEST(XbusEncoder, LegacyMtDataRoundTrip) {
  for (std::uint32_t format : {0u, 1u, 2u, 3u}) {
    XbusLegacyLayout layout;
    layout.output_mode = 0x0003 | 0x0004 | 0x0800;
    layout.output_settings = 0x1 | (1u << 2) | (format << 8);  // counter, Euler, format
    Sample in = Full();
    CollectingSink sink;
    XbusDecoder d("mtx", &sink, layout);
    d.Push(xbus::MtData(in, layout), 0);
    ASSERT_EQ(sink.samples.size(), 1u) << format;
    const Sample& out = sink.samples[0];
    EXPECT_EQ(out.counter, in.counter);
    ExpectNear(*out.acc_mps2, *in.acc_mps2, 2e-5);
    ExpectNear(*out.mag, *in.mag, 2e-6);
    EXPECT_NEAR(*out.temp_c, *in.temp_c, 1e-5);
  }
  // Without the layout a legacy message is not a sample.
  CollectingSink sink;
  XbusDecoder d("mtx", &sink);
  XbusLegacyLayout layout;
  d.Push(xbus::MtData(Full(), layout), 0);
  EXPECT_TRUE(sink.samples.empty());
  EXPECT_EQ(d.counters().bad_structure, 1u);
}

TEST(Gx2Encoder, RepliesRoundTrip) {
  for (bool little : {false, true}) {
    for (std::uint8_t echo : {std::uint8_t{0xC2}, std::uint8_t{0xCB}}) {
      Gx2Options options;
      options.little_endian_floats = little;
      Sample in = Full();
      CollectingSink sink;
      Gx2Decoder d("gx2", &sink, options);
      d.Push(gx2::ContinuousAck(echo, 1234), 0);
      d.Push(gx2::Reply(echo, in, options), 0);
      ASSERT_EQ(d.counters().frames, 2u);
      ASSERT_EQ(sink.samples.size(), 1u);
      const Sample& out = sink.samples[0];
      ExpectNear(*out.acc_mps2, *in.acc_mps2, 1e-5);
      ExpectNear(*out.gyr_radps, *in.gyr_radps, 1e-6);
      EXPECT_EQ(out.mag.has_value(), echo == 0xCB);
      EXPECT_NEAR(*out.t_device_s, *in.t_device_s, 1e-6);
    }
  }
  EXPECT_EQ(gx2::StartContinuous(0xCB), Hex("C4 C1 29 CB"));
  EXPECT_EQ(gx2::StopContinuous(true), Hex("FA 75 B4"));
}

}  // namespace
}  // namespace turncal::drivers
