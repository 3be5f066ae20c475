#include "protocol/messages.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <string>
#include <vector>

#include "core/sequencing/sequencer.h"
#include "protocol/sequencer_json.h"
#include "turncal/version.h"

namespace turncal::protocol {
namespace {

TEST(Messages, VersionGreetingCarriesProtocolVersion) {
  const auto v = VersionMessage();
  EXPECT_EQ(v["class"], "VERSION");
  EXPECT_EQ(v["proto_major"], 1);
  EXPECT_EQ(v["proto_minor"], 1);
  EXPECT_EQ(v["release"], kVersion);
  // JSON Lines: one object on one line.
  EXPECT_EQ(v.dump().find('\n'), std::string::npos);
}

// A pose record's triad that held its values (a magnetometer slower than the stream) keeps its
// count of values through the journal; a journal from before has none (each sample a value); a
// count of values that cannot be is refused.
TEST(PoseRecordJson, AHeldTriadsValuesRoundTripAndOldJournalsStillParse) {
  PoseRecord r;
  r.t_start_s = 1.0;
  r.t_end_s = 3.0;
  TriadStats mag;
  mag.mean = Eigen::Vector3d(0.2, -0.05, 0.4);
  mag.covariance = Eigen::Matrix3d::Identity() * 2.5e-7;
  mag.count = 200;
  mag.values = 100;
  r.mag = mag;
  TriadStats acc = mag;
  acc.values = 0;
  r.acc = acc;
  nlohmann::json j = ToJson(r);
  EXPECT_EQ(j["mag"]["values"], 100);
  EXPECT_FALSE(j["acc"].contains("values"));
  PoseRecord back;
  std::string error;
  ASSERT_TRUE(ParsePoseRecord(j, &back, &error)) << error;
  ASSERT_TRUE(back.mag && back.acc);
  EXPECT_EQ(back.mag->values, 100);
  EXPECT_EQ(IndependentCount(*back.mag), 100);
  EXPECT_EQ(IndependentCount(*back.acc), 200);
  j["mag"].erase("values");
  ASSERT_TRUE(ParsePoseRecord(j, &back, &error)) << error;
  EXPECT_EQ(IndependentCount(*back.mag), 200);
  for (const nlohmann::json& bad :
       {nlohmann::json(201), nlohmann::json(1), nlohmann::json("100")}) {
    j["mag"]["values"] = bad;
    EXPECT_FALSE(ParsePoseRecord(j, &back, &error)) << bad;
  }
}

// noise/DEVICE.json: the profile with the drift the calibrators identified round-trips; a file
// from before it had one still parses; a malformed one is refused with a reason.
TEST(NoiseProfileJson, IdentifiedDriftRoundTripsAndOldFilesStillParse) {
  NoiseProfile p;
  p.sigma[kTriadAcc] = Eigen::Vector3d(0.014, 0.013, 0.015);
  p.sigma[kTriadMag] = Eigen::Vector3d::Constant(5e-4);
  p.rate_hz = 100;
  p.source = "measured over 1.00 s (100 samples)";
  IdentifiedDrift acc;
  acc.drift.gm_sigma = Eigen::Vector3d::Constant(0.058);
  acc.drift.gm_tau_s = 100;
  acc.scale = 2.9;
  acc.poses = 32;
  p.identified_drift[kTriadAcc] = acc;
  p.gyr_bias_temp_c = 31.25;
  p.measured_host_s = std::make_pair(12.5, 13.49);
  const nlohmann::json j = ToJson(p);
  NoiseProfile back;
  std::string error;
  ASSERT_TRUE(ParseNoiseProfile(j, &back, &error)) << error;
  ASSERT_TRUE(back.identified_drift[kTriadAcc].has_value());
  EXPECT_FALSE(back.identified_drift[kTriadMag].has_value());
  EXPECT_EQ(back.identified_drift[kTriadAcc]->scale, 2.9);
  EXPECT_EQ(back.identified_drift[kTriadAcc]->poses, 32);
  EXPECT_EQ(back.identified_drift[kTriadAcc]->drift.gm_sigma, acc.drift.gm_sigma);
  EXPECT_EQ(back.identified_drift[kTriadAcc]->drift.gm_tau_s, 100);
  EXPECT_EQ(back.gyr_bias_temp_c, 31.25);
  ASSERT_TRUE(back.measured_host_s.has_value());
  EXPECT_EQ(back.measured_host_s->first, 12.5);
  EXPECT_EQ(back.measured_host_s->second, 13.49);

  nlohmann::json old = j;
  old.erase("identified_drift");
  ASSERT_TRUE(ParseNoiseProfile(old, &back, &error)) << error;
  EXPECT_FALSE(back.identified_drift[kTriadAcc].has_value());
  old.erase("gyr_bias_temp_c");
  old.erase("measured_host_s");
  ASSERT_TRUE(ParseNoiseProfile(old, &back, &error)) << error;
  EXPECT_TRUE(std::isnan(back.gyr_bias_temp_c));
  EXPECT_FALSE(back.measured_host_s.has_value());

  nlohmann::json bad = j;
  bad["identified_drift"]["acc"]["scale"] = -1;
  EXPECT_FALSE(ParseNoiseProfile(bad, &back, &error));
  EXPECT_NE(error.find("identified drift"), std::string::npos) << error;
}

TEST(Messages, ErrorCarriesItsMessage) {
  const auto e = ErrorMessage("unknown command 'foo'");
  EXPECT_EQ(e["class"], "ERROR");
  EXPECT_EQ(e["message"], "unknown command 'foo'");
}

// The lines and refusals a framer gives for `stream` pushed in reads of `read` bytes. A refusal
// says "discarded" when the line ended in the read, "discarded up to its end" when it had not:
// with `messages` false, only that it was refused.
std::vector<std::string> Frame(const std::string& stream, std::size_t read, std::size_t cap,
                               bool messages = true) {
  RequestFramer framer(cap);
  std::vector<std::string> out;
  for (std::size_t at = 0; at < stream.size(); at += read) {
    framer.Push(
        std::string_view(stream).substr(at, read),
        [&](const std::string& line) {
          out.push_back("line " + line);
          return true;
        },
        [&](const std::string& message) {
          out.push_back(messages ? "refused " + message : "refused");
          return true;
        });
  }
  return out;
}

TEST(Requests, LinesAndRefusalsDoNotDependOnTheReads) {
  // Found by request_fuzz: a line of exactly the cap ending in "\r\n" was refused when a read
  // ended between '\r' and '\n', and accepted otherwise.
  const std::string stream =
      "\x90{\"cmd\":\"ose\"}\n{\":dm\"n\"cext_poiohn\",\"id\"phi:2,\"pad\":"
      "\"xxxxxxxxxxxxxxx\xfe\xff\xff\xffx\"}\n{\"cmd\xcc:\"resul\xb2t\"}\r\n"
      "{\"cmd\":\"devic";
  const std::string lines = stream.substr(1);  // byte 0 chose the cap of 17 in the fuzzer
  const auto whole = Frame(lines, lines.size(), 17);
  ASSERT_EQ(whole.size(), 3u);
  EXPECT_EQ(whole[0], "line {\"cmd\":\"ose\"}");
  EXPECT_EQ(whole[1], "refused request longer than 17 bytes: discarded");
  EXPECT_EQ(whole[2], "line {\"cmd\xcc:\"resul\xb2t\"}");
  const std::vector<std::string> kinds = {whole[0], "refused", whole[2]};
  for (std::size_t read = 1; read <= lines.size(); ++read) {
    EXPECT_EQ(Frame(lines, read, 17, false), kinds) << read;
  }
  // One byte more is refused, in one read or as soon as it is there.
  EXPECT_EQ(Frame("0123456789abcdefgh\r\n", 100, 17),
            std::vector<std::string>{"refused request longer than 17 bytes: discarded"});
  EXPECT_EQ(
      Frame("0123456789abcdefgh\r\n", 1, 17),
      std::vector<std::string>{"refused request longer than 17 bytes: discarded up to its end"});
}

TEST(Requests, LinesParseToObjectsOrErrors) {
  nlohmann::json request;
  std::string error;
  EXPECT_EQ(ParseRequestLine(" \t", &request, &error), RequestLine::kBlank);
  EXPECT_EQ(ParseRequestLine("hello", &request, &error), RequestLine::kError);
  EXPECT_EQ(error, "malformed request: not JSON (one object per line)");
  EXPECT_EQ(ParseRequestLine("[1,2]", &request, &error), RequestLine::kError);
  EXPECT_EQ(error, "malformed request: a JSON object with \"cmd\" expected");
  ASSERT_EQ(ParseRequestLine(R"({"cmd":"calibrate","id":6})", &request, &error),
            RequestLine::kRequest);
  std::string cmd;
  EXPECT_FALSE(ParseCommand(request, &cmd, &error));
  EXPECT_EQ(error.rfind("unknown command 'calibrate' (commands: status,", 0), 0u) << error;
  EXPECT_FALSE(ParseCommand({{"id", 5}}, &cmd, &error));
  EXPECT_EQ(error.rfind("malformed request: no \"cmd\"", 0), 0u) << error;
  EXPECT_TRUE(ParseCommand({{"cmd", "next_pose"}}, &cmd, &error));
  EXPECT_EQ(cmd, "next_pose");
}

TEST(Requests, ArgumentsOfTheWrongTypeAreErrorsNotExceptions) {
  // Found by request_fuzz: json::value() threw on these, and the exception out of the request
  // handler ended turncald -- for next_pose, from any client that may connect.
  std::string device = "x", note = "x", error;
  EXPECT_NO_THROW(EXPECT_FALSE(ParseNextPoseRequest(
      nlohmann::json::parse(R"({"cmd":"next_pose","device":1})"), &device, nullptr, &error)));
  EXPECT_EQ(error, "next_pose: 'device' must be a device name");
  EXPECT_NO_THROW(EXPECT_FALSE(
      ParseResetRequest(nlohmann::json::parse(R"({"cmd":"reset","note":null})"), &note, &error)));
  EXPECT_EQ(error, "reset: 'note' must be a string");
  PublishRequest p;
  error.clear();
  EXPECT_NO_THROW(EXPECT_FALSE(ParsePublishRequest(
      nlohmann::json::parse(
          R"({"cmd":"publish","override":"imu1","mgdel":"accel13","operator":)"
          R"("A. Enginee2147483648r","reason":"re-issue after the fixture audit","id":3})"),
      &p, &error)));
  EXPECT_EQ(error.rfind("publish: an explicit operator override needs", 0), 0u) << error;
  EXPECT_NO_THROW(EXPECT_FALSE(ParsePublishRequest(
      {{"override", true}, {"device", "imu1"}, {"model", 13}, {"operator", "A"}, {"reason", "r"}},
      &p, &error)));
  // What was valid stays valid.
  bool batch = true;
  EXPECT_TRUE(ParseNextPoseRequest({{"cmd", "next_pose"}}, &device, &batch, &error));
  EXPECT_EQ(device, "");
  EXPECT_FALSE(batch);
  EXPECT_TRUE(ParseNextPoseRequest({{"device", "imu2"}}, &device, &batch, &error));
  EXPECT_EQ(device, "imu2");
  // The whole fixture (issue 38).
  device.clear();
  EXPECT_TRUE(ParseNextPoseRequest({{"batch", true}}, &device, &batch, &error));
  EXPECT_TRUE(batch);
  EXPECT_FALSE(ParseNextPoseRequest({{"batch", 1}}, &device, &batch, &error));
  EXPECT_EQ(error, "next_pose: 'batch' must be true or false");
  EXPECT_FALSE(
      ParseNextPoseRequest({{"batch", true}, {"device", "imu2"}}, &device, &batch, &error));
  EXPECT_EQ(error, "next_pose: give 'device' or 'batch', not both");
  EXPECT_TRUE(ParseResetRequest({{"note", "new IMU batch"}}, &note, &error));
  EXPECT_EQ(note, "new IMU batch");
  ASSERT_TRUE(ParsePublishRequest({{"override", true},
                                   {"device", "imu1"},
                                   {"model", "accel13"},
                                   {"operator", "A"},
                                   {"reason", "r"}},
                                  &p, &error));
  EXPECT_EQ(p.model, "accel13");
}

TEST(Requests, DeviceWriteTakesAModelOrRestoreAndItsFlags) {
  std::string cmd, error;
  ASSERT_TRUE(ParseCommand({{"cmd", "device_write"}}, &cmd, &error));
  EXPECT_TRUE(IsMutatingCommand("device_write"));  // only control peers may write into a device
  DeviceWriteArgs a;
  ASSERT_TRUE(ParseDeviceWriteRequest(
      {{"device", "imu1"}, {"model", "mag13"}, {"save", true}, {"version", 4}}, &a, &error))
      << error;
  EXPECT_EQ(a.device, "imu1");
  EXPECT_EQ(a.model, "mag13");
  EXPECT_TRUE(a.save);
  EXPECT_FALSE(a.dry_run);
  EXPECT_FALSE(a.restore);
  ASSERT_TRUE(a.version);
  EXPECT_EQ(*a.version, 4);
  ASSERT_TRUE(ParseDeviceWriteRequest({{"device", "imu1"}, {"restore", true}}, &a, &error));
  EXPECT_TRUE(a.restore);
  EXPECT_FALSE(a.version);
  // Refused, each with its reason.
  EXPECT_FALSE(ParseDeviceWriteRequest({{"model", "mag13"}}, &a, &error));
  EXPECT_NE(error.find("\"device\""), std::string::npos) << error;
  EXPECT_FALSE(ParseDeviceWriteRequest({{"device", "imu1"}}, &a, &error));
  EXPECT_NE(error.find("either"), std::string::npos) << error;
  EXPECT_FALSE(ParseDeviceWriteRequest({{"device", "imu1"}, {"model", "mag13"}, {"restore", true}},
                                       &a, &error));
  EXPECT_NE(error.find("either"), std::string::npos) << error;
  EXPECT_FALSE(ParseDeviceWriteRequest({{"device", "imu1"}, {"model", "mag13"}, {"save", "yes"}},
                                       &a, &error));
  EXPECT_NE(error.find("true or false"), std::string::npos) << error;
  EXPECT_FALSE(ParseDeviceWriteRequest({{"device", "imu1"}, {"model", "mag13"}, {"version", 0}}, &a,
                                       &error));
  EXPECT_NE(error.find("positive integer"), std::string::npos) << error;
  EXPECT_FALSE(ParseDeviceWriteRequest({{"device", "imu1"}, {"model", 13}}, &a, &error));
  EXPECT_NE(error.find("string"), std::string::npos) << error;
}

TEST(Requests, ALineWithANulByteIsNotJson) {
  // nlohmann::json takes a NUL byte for the end of its input: this was a status request
  // (tests/daemon/hostile_clients_test.py; request_fuzz checks it since).
  nlohmann::json request;
  std::string error;
  for (const std::string& line :
       {std::string("{\"cmd\":\"status\"}\0garbage", 24), std::string("{\"cmd\":\"status\"}\0", 17),
        std::string("{\"cmd\":\"sta\0tus\"}", 17)}) {
    EXPECT_EQ(ParseRequestLine(line, &request, &error), RequestLine::kError) << line.size();
    EXPECT_EQ(error, "malformed request: not JSON (one object per line)");
  }
}

TEST(Requests, NestingDeeperThanTheLimitIsRefusedBeforeParsing) {
  // 64 levels pass; 65 are refused, however the line ends; brackets inside strings do not count.
  nlohmann::json request;
  std::string error;
  auto nested = [](int depth) {
    return "{\"cmd\":\"status\",\"id\":" + std::string(depth - 1, '[') +
           std::string(depth - 1, ']') + "}";
  };
  EXPECT_EQ(ParseRequestLine(nested(kMaxRequestDepth), &request, &error), RequestLine::kRequest);
  for (const std::string& line :
       {nested(kMaxRequestDepth + 1), std::string(30000, '['), std::string(70, '{')}) {
    EXPECT_EQ(ParseRequestLine(line, &request, &error), RequestLine::kError) << line.size();
    EXPECT_EQ(error, "malformed request: nested deeper than 64 levels");
  }
  const std::string quoted = "{\"cmd\":\"status\",\"id\":\"" + std::string(1000, '[') + "\\\"\"}";
  EXPECT_EQ(ParseRequestLine(quoted, &request, &error), RequestLine::kRequest) << error;
}

TEST(Requests, ADocumentedArgumentOfAnotherTypeIsRefused) {
  // These were read as absent: a pose for one device went to every device, and a watch with
  // "enable":[] started watching (tests/daemon/hostile_clients_test.py; request_fuzz checks every
  // documented argument since).
  Announcement a;
  std::string device, error;
  EXPECT_FALSE(ParsePoseRequest(
      nlohmann::json::parse(
          R"({"cmd":"pose","phi_deg":0,"gamma_deg":90,"psi_deg":45,"device":{"name":"imu"}})"),
      0, &a, &device, &error));
  EXPECT_EQ(error, "pose: 'device' must be a device name");
  std::optional<WatchSpec> spec;
  EXPECT_FALSE(
      ParseWatchRequest(nlohmann::json::parse(R"({"cmd":"watch","enable":[]})"), &spec, &error));
  EXPECT_EQ(error, "watch: 'enable' must be true or false");
  ASSERT_TRUE(
      ParseWatchRequest({{"cmd", "watch"}, {"enable", true}, {"raw", true}}, &spec, &error));
  ASSERT_TRUE(spec);
  EXPECT_TRUE(spec->raw);
}

TEST(Requests, APoseRequestIgnoresAnEventKey) {
  // Found while writing request_fuzz: "event" (which names a capture's events) made the request
  // "not a pose", and the daemon answered an ERROR without a message.
  Announcement a;
  std::string device, error;
  ASSERT_TRUE(ParsePoseRequest(
      nlohmann::json::parse(
          R"({"cmd":"pose","event":"x","phi_deg":90,"gamma_deg":0,"psi_deg":45,"device":"imu"})"),
      5, &a, &device, &error))
      << error;
  EXPECT_NEAR(a.pose.phi_rad, M_PI / 2, 1e-15);
  EXPECT_EQ(a.t_host_ns, 5);
  EXPECT_EQ(device, "imu");
  EXPECT_FALSE(
      ParsePoseRequest({{"cmd", "pose"}, {"event", 1}, {"phi_deg", "x"}}, 5, &a, &device, &error));
  EXPECT_EQ(error, "pose: 'phi_deg' must be a finite number (degrees)");
}

TEST(Requests, WatchIntervalsOfTinyRatesAreDefined) {
  // Found while writing request_fuzz: 1e9 / max_rate_hz beyond 2^63 was converted to int64
  // (undefined; UBSan: "inf is outside the range of representable values").
  std::optional<WatchSpec> spec;
  std::string error;
  ASSERT_TRUE(ParseWatchRequest(
      nlohmann::json::parse(R"({"cmd":"watch","raw":true,"max_rate_hz":1e-300})"), &spec, &error));
  ASSERT_TRUE(spec);
  EXPECT_EQ(spec->MinIntervalNs(), std::numeric_limits<std::int64_t>::max());
  spec->max_rate_hz = 2;
  EXPECT_EQ(spec->MinIntervalNs(), 500'000'000);
  spec->max_rate_hz = 0;
  EXPECT_EQ(spec->MinIntervalNs(), 0);
  EXPECT_FALSE(ParseWatchRequest({{"max_rate_hz", -1}}, &spec, &error));
  EXPECT_FALSE(error.empty());
  ASSERT_TRUE(ParseWatchRequest({{"enable", false}}, &spec, &error));
  EXPECT_FALSE(spec);
}

}  // namespace
}  // namespace turncal::protocol
