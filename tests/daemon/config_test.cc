// turncald's TOML configuration: the shipped example parses to the documented defaults; typos,
// wrong types and impossible values are errors that name the key and line.

#include "daemon/service/config.h"

#include <gtest/gtest.h>

#include <cstdlib>
#include <fstream>

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
  EXPECT_TRUE(c.station.drift_model);
  EXPECT_EQ(c.station.bias_tau_s, 100.0);
  EXPECT_EQ(c.station.warmup_in_instabilities, 0.0);
  const TableMotion table;
  EXPECT_EQ(c.station.table.rate_dps, table.rate_dps);
  EXPECT_EQ(c.station.table.accel_dps2, table.accel_dps2);
  EXPECT_EQ(c.station.table.settle_s, table.settle_s);
  EXPECT_EQ(c.station.plan_objective, PlanObjective::kTime);
}

TEST(Config, TheTablesMotionAndWhatThePlannerMinimises) {
  Config c;
  std::string error;
  ASSERT_TRUE(
      ParseConfig("[table]\nrate_dps = [50, 30, 10]\naccel_dps2 = 100\nsettle_s = 2.5\n"
                  "plan_for = \"poses\"\n",
                  "t.toml", &c, &error))
      << error;
  EXPECT_EQ(c.station.table.rate_dps, Eigen::Vector3d(50, 30, 10));
  EXPECT_EQ(c.station.table.accel_dps2, Eigen::Vector3d::Constant(100));
  EXPECT_EQ(c.station.table.settle_s, 2.5);
  EXPECT_EQ(c.station.plan_objective, PlanObjective::kPoses);
}

TEST(Config, TheGatesRedundancyFollowsTheClassUnlessSet) {
  Config c;
  std::string error;
  ASSERT_TRUE(ParseConfig("[station]\nsensor_class = \"consumer\"\n", "t.toml", &c, &error))
      << error;
  EXPECT_EQ(c.station.gate.min_dof, 6);
  ASSERT_TRUE(ParseConfig("[station]\nsensor_class = \"consumer\"\n[gate]\nmin_dof = 4\n", "t.toml",
                          &c, &error))
      << error;
  EXPECT_EQ(c.station.gate.min_dof, 4);
  ASSERT_TRUE(ParseConfig("", "t.toml", &c, &error)) << error;
  EXPECT_EQ(c.station.gate.min_dof, 3);
}

TEST(Config, CalibrationsOverTemperature) {
  Config c;
  std::string error;
  ASSERT_TRUE(ParseConfig(
      "[station]\nmodels = [\"accel13@T\", \"mag13\"]\n[thermal]\nmax_order = 2\nt0_c = 20\n"
      "drop_below_sigmas = 0.5\nmin_span_c = 15\ngrid_points = 11\nsoak_rate_c_per_min = 0.1\n"
      "soak_window_s = 120\nsoak_timeout_s = 1800\nsoak_check_bias = false\n",
      "t.toml", &c, &error))
      << error;
  EXPECT_EQ(c.station.models, (std::vector<std::string>{"accel13@T", "mag13"}));
  EXPECT_EQ(c.station.thermal.fit.max_order, 2);
  EXPECT_EQ(c.station.thermal.fit.t0_c, 20.0);
  EXPECT_EQ(c.station.thermal.fit.drop_below_sigmas, 0.5);
  EXPECT_EQ(c.station.thermal.gate.min_span_c, 15.0);
  EXPECT_EQ(c.station.thermal.gate.grid_points, 11);
  EXPECT_EQ(c.station.thermal.soak.max_rate_c_per_min, 0.1);
  EXPECT_EQ(c.station.thermal.soak.window_s, 120.0);
  EXPECT_EQ(c.station.thermal.soak.timeout_s, 1800.0);
  EXPECT_FALSE(c.station.thermal.soak.check_bias);
  EXPECT_FALSE(ParseConfig("[thermal]\nsoak_check_bias = 1\n", "t.toml", &c, &error));
  EXPECT_NE(error.find("'soak_check_bias' must be true or false"), std::string::npos) << error;
  EXPECT_FALSE(ParseConfig("[thermal]\nsoak_rate_c_per_min = 0\n", "t.toml", &c, &error));
  EXPECT_NE(error.find("soak_rate_c_per_min"), std::string::npos) << error;
  EXPECT_FALSE(ParseConfig("[thermal]\nmax_oder = 2\n", "t.toml", &c, &error));
  EXPECT_NE(error.find("max_oder"), std::string::npos) << error;
  EXPECT_FALSE(ParseConfig("[station]\nmodels = [\"mag22@T\"]\n", "t.toml", &c, &error));
  EXPECT_NE(error.find("gauge"), std::string::npos) << error;
  EXPECT_FALSE(ParseConfig("[thermal]\nmin_span_c = -1\n", "t.toml", &c, &error));
  EXPECT_NE(error.find("min_span_c"), std::string::npos) << error;
}

TEST(Config, TheDriftModelsSettings) {
  Config c;
  std::string error;
  ASSERT_TRUE(ParseConfig("[station]\nbias_tau_s = 300\nwarmup = 2.5\nwarmup_tau_s = 90\n",
                          "t.toml", &c, &error))
      << error;
  EXPECT_TRUE(c.station.drift_model);
  EXPECT_EQ(c.station.bias_tau_s, 300.0);
  EXPECT_EQ(c.station.warmup_in_instabilities, 2.5);
  EXPECT_EQ(c.station.warmup_tau_s, 90.0);
  ASSERT_TRUE(ParseConfig("[station]\ndrift_model = \"independent\"\n", "t.toml", &c, &error))
      << error;
  EXPECT_FALSE(c.station.drift_model);
  EXPECT_TRUE(c.station.identify_drift);
  ASSERT_TRUE(ParseConfig("[station]\nidentify_drift = false\n", "t.toml", &c, &error)) << error;
  EXPECT_FALSE(c.station.identify_drift);
  // The noise prior turncal noise measured on this sensor, instead of the class's.
  ASSERT_TRUE(ParseConfig(
      "[station]\nacc_noise_density = 4e-4\nacc_bias_instability = 2e-3\nmag_noise_rms = 6e-4\n"
      "mag_bias_instability = 3e-4\nacc_random_walk = 1e-5\nmag_random_walk = 0\n",
      "t.toml", &c, &error))
      << error;
  EXPECT_EQ(c.station.acc_noise_density, 4e-4);
  EXPECT_EQ(c.station.acc_bias_instability, 2e-3);
  EXPECT_EQ(c.station.mag_noise_rms, 6e-4);
  EXPECT_EQ(c.station.mag_bias_instability, 3e-4);
  EXPECT_EQ(c.station.acc_random_walk, 1e-5);
  EXPECT_EQ(c.station.mag_random_walk, 0.0);
}

TEST(Config, DevicesHaveTheirOwnModelsGatesRatesAndTheLabsReference) {
  Config c;
  std::string error;
  ASSERT_TRUE(ParseConfig(R"(
socket_group = "dialout"
control_users = ["root", 1000]
[gate]
scale_factor = 2e-4
[reference]
g_ned = [0, 0, 9.81]
B_ned = [0.2, 0.0, 0.45]
[[device]]
name = "a"
protocol = "gx2"
port = "/dev/ttyUSB0"
models = ["accel12"]
rate_hz = 200
[device.gate]
angle_deg = 0.02
[[device]]
name = "b"
protocol = "xbus"
port = "/dev/ttyUSB1"
configure = false
)",
                          "t.toml", &c, &error))
      << error;
  EXPECT_EQ(*c.socket_group, "dialout");
  EXPECT_EQ(c.control_uids, (std::vector<unsigned>{0, 1000}));
  EXPECT_EQ(c.station.context.reference.g_ned, Eigen::Vector3d(0, 0, 9.81));
  EXPECT_EQ(c.station.context.reference.B_ned, Eigen::Vector3d(0.2, 0.0, 0.45));
  ASSERT_EQ(c.station.per_device.count("a"), 1u);
  const DeviceModelOptions& a = c.station.per_device.at("a");
  EXPECT_EQ(*a.models, std::vector<std::string>{"accel12"});
  // The device's gate starts from the station's [gate] and changes only what it names.
  EXPECT_EQ(a.gate->tolerances.scale_factor, 2e-4);
  EXPECT_NEAR(a.gate->tolerances.angle_rad, 0.02 * M_PI / 180, 1e-15);
  EXPECT_EQ(c.station.per_device.count("b"), 0u);
  EXPECT_EQ(c.device_settings.at("a").rate_hz, 200.0);
  EXPECT_TRUE(c.device_settings.at("a").configure);
  EXPECT_FALSE(c.device_settings.at("b").configure);
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
        Bad{"[station]\nbias_tau_s = 0\n", "bias_tau_s and warmup_tau_s must be > 0"},
        Bad{"[station]\nwarmup = -1\n", "warmup >= 0"},
        Bad{"[station]\ndrift_model = \"ar1\"\n", "drift_model must be"},
        Bad{"[table]\nrate_dps = 0\n", "[table] table rates and accelerations must be"},
        Bad{"[table]\naccel_dps2 = [1, 2]\n", "'accel_dps2' must be [x, y, z]"},
        Bad{"[table]\nplan_for = \"speed\"\n", "plan_for must be \"time\" or \"poses\""},
        Bad{"[table]\nrate = 3\n", "unknown key 'rate' in [table]"},
        Bad{"[gate]\nmin_dof = 2.5\n", "'min_dof' must be a whole number from 0 to 1000"},
        Bad{"[station]\nidentify_drift = 1\n", "'identify_drift' must be true or false"},
        Bad{"[station]\nacc_bias_instability = 0\n", "acc_bias_instability must be > 0"},
        Bad{"[station]\nmag_random_walk = -1e-6\n", "mag_random_walk must be >= 0"},
        Bad{"[station]\nacc_noise_density = \"4e-4\"\n", "'acc_noise_density' must be a number"},
        Bad{"[[device]]\nname = \"a\"\nprotocol = \"mip\"\nport = \"/dev/x\"\nconfigure = 1\n",
            "'configure' must be true or false"},
        Bad{"[[device]]\nname = \"a\"\nprotocol = \"mip\"\nport = \"/dev/x\"\n[[device]]\nname = "
            "\"a\"\nprotocol = \"xbus\"\nport = \"/dev/y\"\n",
            "device name 'a' is given twice"},
        Bad{"[[device]]\nname = \"a\"\nprotocol = \"nmea\"\nport = \"/dev/x\"\n", "device:"},
        Bad{"socket = 3\n", "t.toml:1: 'socket' must be a string"},
        Bad{"[gate.parameters]\nSx = 0\n", "gate tolerance 'Sx' must be a number > 0"},
        Bad{"this is not toml\n", "t.toml:1:"},
        Bad{"[reference]\ng_ned = [0, 9.8]\n", "t.toml:2: 'g_ned' must be [x, y, z]"},
        Bad{"control_users = [\"no-such-user-here\"]\n", "no user 'no-such-user-here'"},
        Bad{"[[device]]\nname = \"a\"\nprotocol = \"mip\"\nport = \"/dev/x\"\nmodels = "
            "[\"mag99\"]\n",
            "mag99"},
        Bad{"[[device]]\nname = \"a\"\nprotocol = \"mip\"\nport = \"/dev/x\"\n[device.gate]\n"
            "angel_deg = 1\n",
            "unknown key 'angel_deg' in [device.gate]"},
        Bad{"[[device]]\nname = \"a\"\nprotocol = \"mip\"\nport = \"/dev/x\"\nrate_hz = 0\n",
            "'rate_hz' must be in (0, 4000]"}));

// Found by config_fuzz (tests/fuzz), from its crashing inputs: each was accepted with another
// value than the file's, refused without the file and line, threw out of ParseConfig (turncald
// died at start or on SIGHUP), or was undefined behaviour.
INSTANTIATE_TEST_SUITE_P(
    FoundByFuzzing, ConfigErrors,
    ::testing::Values(
        // Taken as the default 115200.
        Bad{"[[device]]\nname = \"imu2\"\nprotocol = \"mip\"\nport = \"/dev/x\"\nbaud = -921600\n",
            "t.toml:5: 'baud' must be a whole number from 300 to 4000000"},
        // Converted to long long: undefined.
        Bad{"[[device]]\nname = \"a\"\nprotocol = \"mip\"\nport = \"/dev/x\"\nbaud = 1e300\n",
            "t.toml:5: 'baud' must be a whole number from 300 to 4000000"},
        // Taken as xbus on the port ":/dev/ttyUSB1".
        Bad{"[[device]]\nname = \"imu1\"\nprotocol = \"xbus:\"\nport = \"/dev/ttyUSB1\"\nbaud = "
            "115200\n",
            "t.toml:1: device: unknown protocol 'xbus:'"},
        // The gate's own check said neither file nor line.
        Bad{"[gate]\nmax_normalized_residual = 0.0\n",
            "t.toml:1: [gate]: max_normalized_residual must be > 0"},
        // toml++ converted the float to int64_t: undefined.
        Bad{"control_users = [1e301]\n", "t.toml:1: 'control_users' holds user names or uids"},
        // Wrapped to another uid beyond 2^32; std::stoul threw beyond 2^64.
        Bad{"control_users = [\"root\", 1000429496727296]\n",
            "t.toml:1: control_users: uid 1000429496727296 is out of range"},
        Bad{"control_users = [\"99999999999999999999\"]\n",
            "uid 99999999999999999999 is out of range"}));

TEST(Config, APortKeepsItsAtSign) {
  // Without a baud, "/dev/odd@9600" was the port "/dev/odd" at 9600 baud.
  for (const char* baud : {"", "baud = 57600\n"}) {
    Config c;
    std::string error;
    ASSERT_TRUE(ParseConfig(std::string("[[device]]\nname = \"a\"\nprotocol = \"mip\"\nport = "
                                        "\"/dev/odd@9600\"\n") +
                                baud,
                            "t.toml", &c, &error))
        << error;
    ASSERT_EQ(c.devices.size(), 1u);
    EXPECT_EQ(c.devices[0].port, "/dev/odd@9600");
    EXPECT_EQ(c.devices[0].baud, *baud ? 57600 : 115200);
  }
}

// A device has one calibration of each model (one calibrations/DEVICE.MODEL.json, one entry in
// status and RESULT): a model named twice is refused with its name, for the station, for one
// device, and with the free pose source.
TEST(Config, AModelListedTwiceIsRefused) {
  Config c;
  std::string error;
  EXPECT_FALSE(ParseConfig("[station]\nmodels = [\"accel13\", \"mag13\", \"accel13\"]\n", "t.toml",
                           &c, &error));
  EXPECT_NE(error.find("model 'accel13' is listed twice"), std::string::npos) << error;
  EXPECT_FALSE(ParseConfig("[station]\npose_source = \"free\"\nmodels = [\"accel9\", \"accel9\"]\n",
                           "t.toml", &c, &error));
  EXPECT_NE(error.find("model 'accel9' is listed twice"), std::string::npos) << error;
  EXPECT_FALSE(
      ParseConfig("[[device]]\nname = \"a\"\nprotocol = \"mip\"\nport = \"/dev/ttyUSB0\"\n"
                  "models = [\"mag13\", \"mag13\"]\n",
                  "t.toml", &c, &error));
  EXPECT_NE(error.find("device 'a': model 'mag13' is listed twice"), std::string::npos) << error;
  ASSERT_TRUE(ParseConfig("[station]\nmodels = [\"accel13\", \"mag13\"]\n", "t.toml", &c, &error))
      << error;
}

}  // namespace
}  // namespace turncal::daemon

namespace turncal::daemon {
namespace {

// Issue 38: a fixture's slots and their mounts, inline or in a file of their own, and each
// device's slot or mount.
TEST(Config, AFixturesSlotsGiveTheirDevicesMounts) {
  const std::string devices =
      "[[device]]\nname = \"a\"\nprotocol = \"mip\"\nport = \"/dev/x\"\nslot = \"2\"\n"
      "[[device]]\nname = \"b\"\nprotocol = \"xbus\"\nport = \"/dev/y\"\nmount = [0, 0, 45]\n"
      "[[device]]\nname = \"c\"\nprotocol = \"mip\"\nport = \"/dev/z\"\n";
  Config c;
  std::string error;
  ASSERT_TRUE(
      ParseConfig("[fixture]\nname = \"cube8\"\n[[fixture.slot]]\nname = \"1\"\nmount = "
                  "\"+x+y+z\"\n[[fixture.slot]]\nname = \"2\"\nmount = \"-y+x+z\"\n" +
                      devices,
                  "t.toml", &c, &error))
      << error;
  EXPECT_EQ(c.station.fixture, "cube8");
  ASSERT_EQ(c.fixture.slots.size(), 2u);
  const DeviceModelOptions& a = c.station.per_device.at("a");
  EXPECT_EQ(a.slot, "2");
  ASSERT_TRUE(a.mount.has_value());
  EXPECT_TRUE(a.mount->isApprox(R3(-M_PI / 2)));
  const DeviceModelOptions& b = c.station.per_device.at("b");
  EXPECT_EQ(b.slot, "");
  EXPECT_TRUE(b.mount->isApprox(R3(M_PI / 4)));
  EXPECT_EQ(c.station.per_device.count("c"), 0u);  // the station's context: the identity

  // The same slots from a file of their own, relative to the configuration's folder.
  const std::string dir = ::testing::TempDir() + "/fixture_cfg";
  ASSERT_EQ(std::system(("mkdir -p " + dir).c_str()), 0);
  {
    std::ofstream f(dir + "/cube8.toml");
    f << "name = \"cube8 from its file\"\n[[slot]]\nname = \"1\"\nmount = \"+x+y+z\"\n"
         "[[slot]]\nname = \"2\"\nmount = \"-y+x+z\"\n";
  }
  Config from_file;
  ASSERT_TRUE(ParseConfig("[fixture]\nfile = \"cube8.toml\"\nbatch = \"LOT-117\"\n" + devices,
                          dir + "/turncald.toml", &from_file, &error))
      << error;
  EXPECT_EQ(from_file.station.fixture, "cube8 from its file");
  EXPECT_EQ(from_file.station.batch_id, "LOT-117");  // turncald.toml's, the file has none
  EXPECT_EQ(c.station.batch_id, "");
  EXPECT_EQ(from_file.fixture.file, dir + "/cube8.toml");
  EXPECT_TRUE(from_file.station.per_device.at("a").mount->isApprox(*a.mount));
}

INSTANTIATE_TEST_SUITE_P(
    Fixtures, ConfigErrors,
    ::testing::Values(
        Bad{"[[device]]\nname = \"a\"\nprotocol = \"mip\"\nport = \"/dev/x\"\nmount = \"-y-x+z\"\n",
            "t.toml:5: 'mount': mount '-y-x+z': the axes are left-handed"},
        Bad{"[[device]]\nname = \"a\"\nprotocol = \"mip\"\nport = \"/dev/x\"\nmount = [0, 90]\n",
            "t.toml:5: 'mount' must be the case's axes"},
        Bad{"[[device]]\nname = \"a\"\nprotocol = \"mip\"\nport = \"/dev/x\"\nslot = \"1\"\n",
            "t.toml:5: device 'a' is in slot '1' but no [fixture] is configured"},
        Bad{"[fixture]\n[[fixture.slot]]\nname = \"1\"\nmount = \"+x+y+z\"\n[[device]]\nname = "
            "\"a\"\nprotocol = \"mip\"\nport = \"/dev/x\"\nslot = \"9\"\n",
            "device 'a': the fixture has no slot '9' (its slots: 1)"},
        Bad{"[fixture]\n[[fixture.slot]]\nname = \"1\"\nmount = \"+x+y+z\"\n[[device]]\nname = "
            "\"a\"\nprotocol = \"mip\"\nport = \"/dev/x\"\nslot = \"1\"\n[[device]]\nname = "
            "\"b\"\nprotocol = \"mip\"\nport = \"/dev/y\"\nslot = \"1\"\n",
            "device 'b': slot '1' already holds another device"},
        Bad{"[fixture]\n[[fixture.slot]]\nname = \"1\"\nmount = \"+x+y+z\"\n[[fixture.slot]]\n"
            "name = \"1\"\nmount = \"-x-y+z\"\n",
            "slot '1' is named twice"},
        Bad{"[fixture]\n[[fixture.slot]]\nname = \"1\"\n", "a slot needs a name and a mount"},
        Bad{"[fixture]\nname = \"x\"\n", "[fixture] has no [[slot]]"},
        Bad{"[fixture]\nfile = \"/no/such/fixture.toml\"\n", "/no/such/fixture.toml"},
        Bad{"[fixture]\nslots = 3\n", "unknown key 'slots' in [fixture]"},
        Bad{"[fixture]\n[[fixture.slot]]\nname = \"1\"\nmount = \"+x+y+z\"\n[[device]]\nname = "
            "\"a\"\nprotocol = \"mip\"\nport = \"/dev/x\"\nslot = \"1\"\nmount = \"+x+y+z\"\n",
            "device 'a' has a slot and a mount"},
        Bad{"[fixture]\nbatch = 117\n[[fixture.slot]]\nname = \"1\"\nmount = \"+x+y+z\"\n",
            "batch"}));

}  // namespace
}  // namespace turncal::daemon
