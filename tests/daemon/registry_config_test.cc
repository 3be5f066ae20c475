// [registry] (issue 24): the connection string is required, every key checked; the password's
// file is found in systemd's credentials directory and refused when others may read it; the
// idempotency key of a calibration names station, serial, model, version and time.

#include <gtest/gtest.h>
#include <sys/stat.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>

#include "daemon/registry/registry_db.h"
#include "daemon/registry/registry_outbox.h"
#include "daemon/service/config.h"

namespace turncal::daemon {
namespace {

TEST(RegistryConfig, TheSectionIsParsedAndChecked) {
  Config c;
  std::string error;
  ASSERT_TRUE(
      ParseConfig("[registry]\nconninfo = \"host=db.lab dbname=turncal sslmode=verify-full\"\n"
                  "password_file = \"registry-password\"\nstation = \"line-3\"\nretry_max_s = 10\n",
                  "t.toml", &c, &error))
      << error;
  EXPECT_TRUE(c.registry.enabled());
  EXPECT_EQ(c.registry.conninfo, "host=db.lab dbname=turncal sslmode=verify-full");
  EXPECT_EQ(c.registry.password_file, "registry-password");
  EXPECT_EQ(c.registry.station, "line-3");
  EXPECT_EQ(c.registry.retry_max_s, 10.0);

  Config none;
  ASSERT_TRUE(ParseConfig("", "t.toml", &none, &error));
  EXPECT_FALSE(none.registry.enabled());

  EXPECT_FALSE(ParseConfig("[registry]\nstation = \"x\"\n", "t.toml", &c, &error));
  EXPECT_NE(error.find("needs conninfo"), std::string::npos) << error;
  EXPECT_FALSE(
      ParseConfig("[registry]\nconninfo = \"x\"\npasword = \"typo\"\n", "t.toml", &c, &error));
  EXPECT_NE(error.find("unknown key 'pasword' in [registry]"), std::string::npos) << error;
  EXPECT_FALSE(
      ParseConfig("[registry]\nconninfo = \"x\"\nretry_max_s = 0\n", "t.toml", &c, &error));
  EXPECT_NE(error.find("retry_max_s"), std::string::npos) << error;
}

TEST(RegistryConfig, ThePasswordFileIsOnlyReadWhenNobodyElseMay) {
  const auto dir = std::filesystem::temp_directory_path() / "turncal_registry_config_test";
  std::filesystem::create_directories(dir);
  const std::string path = (dir / "pw").string();
  std::ofstream(path) << "hunter2 \r\n";
  ::chmod(path.c_str(), 0600);
  std::string password, error;
  ASSERT_TRUE(ReadPasswordFile(path, &password, &error)) << error;
  EXPECT_EQ(password, "hunter2 ");  // a password may end in a space; the CRLF's CR goes
  // Relative: in systemd's credentials directory.
  ::setenv("CREDENTIALS_DIRECTORY", dir.c_str(), 1);
  EXPECT_EQ(ResolvePasswordFile("pw"), path);
  ASSERT_TRUE(ReadPasswordFile("pw", &password, &error)) << error;
  // systemd's credential with an ACL for the service's user: its mask shows as group bits.
  ::chmod(path.c_str(), 0440);
  EXPECT_TRUE(ReadPasswordFile("pw", &password, &error)) << error;
  ::unsetenv("CREDENTIALS_DIRECTORY");
  ::chmod(path.c_str(), 0640);
  EXPECT_FALSE(ReadPasswordFile(path, &password, &error));
  EXPECT_NE(error.find("may be read by group or others (mode 0640)"), std::string::npos) << error;
  ::chmod(path.c_str(), 0604);  // others, even in the credentials directory
  ::setenv("CREDENTIALS_DIRECTORY", dir.c_str(), 1);
  EXPECT_FALSE(ReadPasswordFile("pw", &password, &error));
  ::unsetenv("CREDENTIALS_DIRECTORY");
  std::ofstream(path, std::ios::trunc) << "\n";
  ::chmod(path.c_str(), 0600);
  EXPECT_FALSE(ReadPasswordFile(path, &password, &error));
  EXPECT_NE(error.find("is empty"), std::string::npos) << error;
  EXPECT_FALSE(ReadPasswordFile((dir / "missing").string(), &password, &error));
  EXPECT_NE(error.find("missing"), std::string::npos) << error;
  std::filesystem::remove_all(dir);
}

TEST(RegistryConfig, TheIdempotencyKeyNamesStationSerialModelVersionAndTime) {
  nlohmann::json c = {{"device", "imu0"},
                      {"model", "accel13"},
                      {"version", 4},
                      {"time", "2026-11-25T10:00:00Z"},
                      {"provenance", {{"device_identity", {{"serial", "6251.12345"}}}}}};
  EXPECT_EQ(RegistryOutbox::CalibrationKey("line-3", c),
            "line-3/6251.12345/accel13/v4/2026-11-25T10:00:00Z");
  c["provenance"]["device_identity"] = {{"device_id", "03700001"}};  // Xbus
  EXPECT_EQ(RegistryOutbox::CalibrationKey("line-3", c),
            "line-3/03700001/accel13/v4/2026-11-25T10:00:00Z");
  c["provenance"]["device_identity"] = nullptr;  // a replay: the device's name
  EXPECT_EQ(RegistryOutbox::CalibrationKey("line-3", c),
            "line-3/imu0/accel13/v4/2026-11-25T10:00:00Z");
}

TEST(RegistryConfig, NoServerIsAClearErrorNotAHang) {
  RegistryDb db;
  RegistryOptions o;
  o.conninfo = "host=/nonexistent/turncal port=1 dbname=turncal";
  std::string error;
  EXPECT_FALSE(db.Connect(o, /*migrate=*/true, &error));
  EXPECT_FALSE(db.connected());
  EXPECT_NE(error.find("cannot connect to the registry"), std::string::npos) << error;
  RegistryDb::PutResult result;
  EXPECT_FALSE(
      db.Put({{"kind", "calibration"}, {"document", nlohmann::json::object()}}, &result, &error));
  EXPECT_FALSE(result.permanent);  // not connected: it may pass later
  EXPECT_FALSE(db.Put({{"kind", "nonsense"}}, &result, &error));
  EXPECT_TRUE(result.permanent);
}

TEST(RegistryConfig, TheMigrationsAreNumberedFromOne) {
  EXPECT_EQ(static_cast<int>(RegistryMigrations().size()), kRegistrySchemaVersion);
}

}  // namespace
}  // namespace turncal::daemon
