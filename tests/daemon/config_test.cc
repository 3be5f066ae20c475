// turncald's TOML configuration: the shipped example parses to the documented defaults; typos,
// wrong types and impossible values are errors that name the key and line.

#include "daemon/config.h"

#include <gtest/gtest.h>

namespace turncal::daemon {
namespace {

TEST(Config, TheShippedExampleParsesToTheDefaults) {
  Config c;
  std::string error;
  ASSERT_TRUE(
      LoadConfig(std::string(TURNCAL_SOURCE_DIR) + "/systemd/turncald.toml.example", &c, &error))
      << error;
  ASSERT_EQ(c.devices.size(), 2u);
  EXPECT_EQ(c.devices[0].name, "imu0");
  EXPECT_EQ(c.devices[0].protocol, drivers::Protocol::kMip);
  EXPECT_EQ(c.devices[1].protocol, drivers::Protocol::kXbus);
  EXPECT_EQ(*c.socket_path, "/run/turncal/turncal.sock");
  const SequencerOptions defaults;
  EXPECT_EQ(c.station.sequencer.dwell_s, defaults.dwell_s);
  EXPECT_EQ(c.station.sequencer.stillness.window_s, defaults.stillness.window_s);
  EXPECT_EQ(c.station.sequencer.stillness.false_alarm, defaults.stillness.false_alarm);
  EXPECT_EQ(c.station.sequencer.max_bad_fraction, defaults.max_bad_fraction);
  EXPECT_EQ(c.station.models, (std::vector<std::string>{"accel13", "mag13"}));
  GateTolerances industrial;
  GateTolerancesForClass("industrial", &industrial);
  EXPECT_EQ(c.station.gate.tolerances.scale_factor, industrial.scale_factor);
}

TEST(Config, ValuesAndPerParameterTolerances) {
  Config c;
  std::string error;
  ASSERT_TRUE(ParseConfig(R"(
[station]
models = ["accel12"]
sensor_class = "consumer"
[sequencer]
dwell_s = 5
[gate]
angle_deg = 0.05
[gate.parameters]
Sx = 2e-4
)",
                          "t.toml", &c, &error))
      << error;
  EXPECT_EQ(c.station.models, std::vector<std::string>{"accel12"});
  EXPECT_EQ(c.station.sequencer.dwell_s, 5.0);
  EXPECT_NEAR(c.station.gate.tolerances.angle_rad, 0.05 * M_PI / 180, 1e-15);
  EXPECT_EQ(c.station.gate.parameter_tolerance.at("Sx"), 2e-4);
  GateTolerances consumer;
  GateTolerancesForClass("consumer", &consumer);
  EXPECT_EQ(c.station.gate.tolerances.scale_factor, consumer.scale_factor);
}

struct Bad {
  const char* text;
  const char* message;
};

class ConfigErrors : public ::testing::TestWithParam<Bad> {};

TEST_P(ConfigErrors, AreNamedWithTheirLine) {
  Config c;
  std::string error;
  EXPECT_FALSE(ParseConfig(GetParam().text, "t.toml", &c, &error));
  EXPECT_NE(error.find(GetParam().message), std::string::npos) << error;
}

INSTANTIATE_TEST_SUITE_P(
    Cases, ConfigErrors,
    ::testing::Values(
        Bad{"[sequencer]\ndwel_s = 3\n", "t.toml:2: unknown key 'dwel_s' in [sequencer]"},
        Bad{"[sequencer]\ndwell_s = \"3\"\n", "t.toml:2: 'dwell_s' must be a number"},
        Bad{"[sequencer]\ndwell_s = -1\n", "dwell must be in (0, 3600] s"},
        Bad{"[station]\nmodels = [\"accel14\"]\n", "accel14"},
        Bad{"[station]\nsensor_class = \"military\"\n", "unknown sensor class 'military'"},
        Bad{"[[device]]\nname = \"a\"\nprotocol = \"mip\"\nport = \"/dev/x\"\n[[device]]\nname = "
            "\"a\"\nprotocol = \"xbus\"\nport = \"/dev/y\"\n",
            "device name 'a' is given twice"},
        Bad{"[[device]]\nname = \"a\"\nprotocol = \"nmea\"\nport = \"/dev/x\"\n", "device:"},
        Bad{"socket = 3\n", "t.toml:1: 'socket' must be a string"},
        Bad{"[gate.parameters]\nSx = 0\n", "gate tolerance 'Sx' must be a number > 0"},
        Bad{"this is not toml\n", "t.toml:1:"}));

}  // namespace
}  // namespace turncal::daemon
