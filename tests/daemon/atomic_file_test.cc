// WriteFileAtomically (daemon/state/atomic_file.h): a regular file is replaced whole; a path that
// is not a regular file is written through and stays what it was; a directory is refused.

#include "daemon/state/atomic_file.h"

#include <gtest/gtest.h>
#include <sys/stat.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <sstream>

namespace turncal::daemon {
namespace {

namespace fs = std::filesystem;

std::string Slurp(const fs::path& path) {
  std::ifstream in(path);
  std::stringstream text;
  text << in.rdbuf();
  return text.str();
}

class AtomicFile : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() /
           ("turncal_atomic_" + std::to_string(::getpid()) + "_" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  fs::path dir_;
};

TEST_F(AtomicFile, ARegularFileIsReplacedWhole) {
  const fs::path path = dir_ / "a.json";
  std::string error;
  ASSERT_TRUE(WriteFileAtomically(path.string(), "first, longer", &error)) << error;
  ASSERT_TRUE(WriteFileAtomically(path.string(), "second", &error)) << error;
  EXPECT_EQ(Slurp(path), "second");
  EXPECT_EQ(std::distance(fs::directory_iterator(dir_), fs::directory_iterator()), 1)
      << "no temporary file is left beside it";
}

// What replaced the host's /dev/null with a regular file (turncald --result-out /dev/null): a
// rename over a path that is not a regular file. A symbolic link stands in for /dev/null and
// /dev/stdout here (a test must not risk the host's /dev/null).
TEST_F(AtomicFile, ALinkIsWrittenThroughAndStaysALink) {
  const fs::path target = dir_ / "target.json", link = dir_ / "out.json";
  { std::ofstream(target) << "old contents, longer"; }
  fs::create_symlink(target, link);
  std::string error;
  ASSERT_TRUE(WriteFileAtomically(link.string(), "new", &error)) << error;
  EXPECT_TRUE(fs::is_symlink(link));
  EXPECT_EQ(Slurp(target), "new");
}

TEST_F(AtomicFile, ADirectoryIsRefusedWithItsName) {
  std::string error;
  EXPECT_FALSE(WriteFileAtomically(dir_.string(), "x", &error));
  EXPECT_NE(error.find(dir_.string()), std::string::npos) << error;
  EXPECT_TRUE(fs::is_directory(dir_));
}

}  // namespace
}  // namespace turncal::daemon
