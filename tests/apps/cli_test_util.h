#pragma once
// Helpers of the cli_test program's files (cli_test.cc, cli_pipeline_test.cc,
// cli_outputs_test.cc, cli_hardening_test.cc, cli_check_test.cc): files in the test's temporary
// directory, the toy data set, fast training flags.
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

// A file's bytes.
inline std::string Slurp(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), {});
}

}  // namespace secure::test::cli
