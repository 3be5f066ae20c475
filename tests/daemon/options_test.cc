#include "daemon/service/options.h"

#include <gtest/gtest.h>

namespace turncal::daemon {
namespace {

// Parses argv as turncald would; returns the CLI11 exit code (0 on success).
int Parse(std::vector<std::string> args, Options* options) {
  CLI::App app;
  AddCommandLine(&app, options);
  std::reverse(args.begin(), args.end());
  try {
    app.parse(args);
  } catch (const CLI::ParseError& e) {
    return e.get_exit_code();
  }
  return 0;
}

TEST(Options, RepeatedDevicesAreParsed) {
  Options o;
  ASSERT_EQ(Parse({"--device", "a=mip:/dev/ttyUSB0@921600", "--device", "b=xbus:/dev/ttyUSB1"}, &o),
            0);
  ASSERT_EQ(o.devices.size(), 2u);
  EXPECT_EQ(o.devices[1].protocol, drivers::Protocol::kXbus);
  std::string error;
  EXPECT_TRUE(o.IsValid(&error)) << error;
}

TEST(Options, BadDeviceOrProtocolIsAParseError) {
  Options o;
  EXPECT_NE(Parse({"--device", "a=foo:/dev/x"}, &o), 0);
  Options p;
  EXPECT_NE(Parse({"--protocol", "nmea"}, &p), 0);
}

TEST(Options, InconsistentFlagsAreRejectedWithAReason) {
  std::string error;
  Options once;
  once.once = true;
  EXPECT_FALSE(once.IsValid(&error));
  EXPECT_NE(error.find("--replay"), std::string::npos);
  Options dup;
  ASSERT_EQ(Parse({"--device", "a=mip:/dev/x", "--device", "a=gx2:/dev/y"}, &dup), 0);
  EXPECT_FALSE(dup.IsValid(&error));
  EXPECT_NE(error.find("twice"), std::string::npos);
}

}  // namespace
}  // namespace turncal::daemon
