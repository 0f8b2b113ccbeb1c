#pragma once
// Helpers shared by the unit tests (include as "tests/test_util.h").

#include <gtest/gtest.h>

#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "secure/common/error.h"

namespace secure::test {

/// The message of the secure::Error thrown by `fn`; a test failure if `fn` throws none.
template <typename Fn>
std::string ErrorOf(Fn&& fn) {
  try {
    fn();
  } catch (const secure::Error& e) {
    return e.what();
  }
  ADD_FAILURE() << "expected secure::Error";
  return "";
}

/// Expects `message` to contain every one of `parts`, naming each that it lacks.
inline void ExpectContainsAll(const std::string& message, const std::vector<std::string>& parts) {
  for (const std::string& part : parts) {
    EXPECT_NE(message.find(part), std::string::npos)
        << "message '" << message << "' lacks '" << part << "'";
  }
}

/// A fresh directory per test (named after the test and the process, since ctest runs tests in
/// parallel processes), removed afterwards.
class TempDirTest : public ::testing::Test {
 protected:
  void SetUp() override {
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    dir_ = std::filesystem::path(::testing::TempDir()) /
           ("secure_" + std::string(info->test_suite_name()) + "_" + info->name() + "_" +
            std::to_string(::getpid()));
    std::filesystem::remove_all(dir_);
    std::filesystem::create_directories(dir_);
  }
  void TearDown() override {
    if (!std::getenv("SECURE_KEEP_TEST_DIRS")) std::filesystem::remove_all(dir_);
  }

  /// Writes `content` to <dir>/<name> and returns the path.
  std::string Write(const std::string& name, const std::string& content) {
    const std::string path = PathOf(name);
    std::ofstream(path, std::ios::binary) << content;
    return path;
  }
  std::string PathOf(const std::string& name) const { return (dir_ / name).string(); }

  std::filesystem::path dir_;
};

}  // namespace secure::test

/// Expects `haystack` (a message) to contain `needle`, printing both otherwise.
#define EXPECT_HAS(haystack, needle)                               \
  EXPECT_NE(std::string(haystack).find(needle), std::string::npos) \
      << "message: " << (haystack) << "\nexpected to contain: " << (needle)
