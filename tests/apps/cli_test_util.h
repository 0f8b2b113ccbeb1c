#pragma once
// Helpers of the cli_test program's files (cli_test.cc, cli_pipeline_test.cc,
// cli_outputs_test.cc, cli_hardening_test.cc, cli_check_test.cc): files in the test's temporary
// directory, the toy data set and its `cbf train` (TrainToyArgs), fast training flags, a small
// double-integrator barrier (TrainDoubleIntegratorBarrier), a rejected run (ExpectRejected).
// Each file: #include "tests/apps/cli_test_util.h", then `using namespace secure::test::cli;`.
#include <gtest/gtest.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "tests/apps/cli_run.h"
#include "tests/test_util.h"

namespace secure::test::cli {

namespace fs = std::filesystem;
using Result = CliResult;
using secure::test::ExpectOneErrorLine;
using secure::test::RunCli;

inline std::filesystem::path TempDir() { return CliTempDir(); }

inline std::string Write(const std::string& name, const std::string& content) {
  const std::filesystem::path p = TempDir() / name;
  std::ofstream(p) << content;
  return p.string();
}

// A separable 2-D data set: safe states have x > 0.2, near-dangerous x < -0.2.
inline void WriteToyData() {
  std::string safe = "x,y,extra\n", nd = "y,x\n";
  for (int i = 0; i < 60; ++i) {
    const double y = -1.0 + 2.0 * i / 59.0;
    safe += std::to_string(0.3 + 0.01 * i) + "," + std::to_string(y) + ",7\n";
    nd += std::to_string(y) + "," + std::to_string(-0.3 - 0.01 * i) + "\n";
  }
  Write("safe.csv", safe);
  Write("nd.csv", nd);
}

inline const std::string kFastTrain = " --epochs 30 --hidden 8,8 --lr 0.01 --final-lr 0.001";

// `cbf train` of a small barrier on the toy data set (written first) into `out`.
inline std::string TrainToyArgs(const std::string& out) {
  WriteToyData();
  return "cbf train --safe-states " + (TempDir() / "safe.csv").string() +
         " --near-dangerous-states " + (TempDir() / "nd.csv").string() + " --features x,y" +
         kFastTrain + " --out " + out;
}

// A run of `secure <args>` that must fail as bad input: exit code 1 and `needle` on stderr.
inline Result ExpectRejected(const std::string& args, const std::string& needle) {
  Result r = RunCli(args);
  EXPECT_EQ(r.exit_code, 1) << args;
  EXPECT_HAS(r.err, needle);
  return r;
}

// Trains a small double-integrator barrier into `model` with `secure cbf train --domain
// double-integrator <flags>` (the data and network sizes) and asserts that it succeeded (call
// with ASSERT_NO_FATAL_FAILURE).
inline void TrainDoubleIntegratorBarrier(const std::string& flags, const std::string& model) {
  const Result r = RunCli("cbf train --domain double-integrator " + flags + " --out " + model);
  ASSERT_EQ(r.exit_code, 0) << r.err;
}

// A file's bytes.
inline std::string Slurp(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), {});
}

}  // namespace secure::test::cli
