#pragma once
// Running the real `secure` binary (SECURE_CLI) from a test: RunCli captures its exit code,
// stdout and stderr; ExpectOneErrorLine checks the form of every CLI error. Shared by
// cli_test.cc and cli_domains_test.cc (one temporary directory per test process, removed after a
// run that passed).
#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>

#include "tests/test_util.h"

namespace secure::test {

struct CliResult {
  int exit_code;
  std::string out;  // stdout
  std::string err;  // stderr
};

// One directory per test process: ctest runs the tests of a file as parallel processes
// (secure_<program>_<pid>, e.g. secure_cli_test_123).
inline std::filesystem::path CliTempDir() {
  static const std::filesystem::path dir = [] {
    std::filesystem::path d =
        std::filesystem::path(::testing::TempDir()) /
        ("secure_" + std::string(program_invocation_short_name) + "_" + std::to_string(::getpid()));
    std::filesystem::remove_all(d);
    std::filesystem::create_directories(d);
    return d;
  }();
  return dir;
}

// Removes the directory after the run unless a test failed (its files help to debug it).
class RemoveCliTempDirOnSuccess : public ::testing::Environment {
 public:
  void TearDown() override {
    if (::testing::UnitTest::GetInstance()->Passed()) std::filesystem::remove_all(CliTempDir());
  }
};
[[maybe_unused]] inline ::testing::Environment* const kRemoveCliTempDir =
    ::testing::AddGlobalTestEnvironment(new RemoveCliTempDirOnSuccess);

// Runs `secure <args>`; stdout and stderr are captured through files.
inline CliResult RunCli(const std::string& args) {
  const std::filesystem::path out = CliTempDir() / "stdout.txt", err = CliTempDir() / "stderr.txt";
  const std::string cmd =
      std::string(SECURE_CLI) + " " + args + " >" + out.string() + " 2>" + err.string();
  const int status = std::system(cmd.c_str());
  auto slurp = [](const std::filesystem::path& p) {
    std::ifstream in(p);
    return std::string(std::istreambuf_iterator<char>(in), {});
  };
  return {WIFEXITED(status) ? WEXITSTATUS(status) : -1, slurp(out), slurp(err)};
}

// The error line of a failed run: exit code 1, exactly one line on stderr, with the prefix.
inline void ExpectOneErrorLine(const CliResult& r, const std::string& needle) {
  EXPECT_EQ(r.exit_code, 1) << r.err;
  EXPECT_EQ(r.err.rfind("secure: error: ", 0), 0u) << r.err;
  EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
  EXPECT_HAS(r.err, needle);
}

}  // namespace secure::test
