#include "protocol/messages.h"

#include <gtest/gtest.h>

#include "turncal/version.h"

namespace turncal::protocol {
namespace {

TEST(Messages, VersionGreetingCarriesProtocolVersion) {
  const auto v = VersionMessage();
  EXPECT_EQ(v["class"], "VERSION");
  EXPECT_EQ(v["proto_major"], 1);
  EXPECT_EQ(v["proto_minor"], 0);
  EXPECT_EQ(v["release"], kVersion);
  // JSON Lines: one object on one line.
  EXPECT_EQ(v.dump().find('\n'), std::string::npos);
}

TEST(Messages, ErrorCarriesItsMessage) {
  const auto e = ErrorMessage("unknown command 'foo'");
  EXPECT_EQ(e["class"], "ERROR");
  EXPECT_EQ(e["message"], "unknown command 'foo'");
}

}  // namespace
}  // namespace turncal::protocol
