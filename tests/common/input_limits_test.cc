// Resource limits on inputs (issue 34, secure/common/input_limits.h): only regular files of
// bounded size are read (a FIFO without a writer, /dev/zero and a directory each fail at once
// with one line naming the path), and YAML documents are bounded in nodes (aliases expanded)
// and depth. One test per limit, each with the limit raised to show it is the limit that bites.
#include "secure/common/input_limits.h"

#include <sys/stat.h>
#include <unistd.h>

#include <filesystem>
#include <string>

#include <gtest/gtest.h>

#include "secure/common/atomic_file.h"
#include "secure/common/yaml_limits.h"
#include "tests/test_util.h"

namespace secure {
namespace {

namespace fs = std::filesystem;
using test::ErrorOf;

class InputLimitsTest : public test::TempDirTest {
 protected:
  void SetUp() override {
    TempDirTest::SetUp();
    saved_ = GetInputLimits();
  }
  void TearDown() override {
    SetInputLimits(saved_);
    TempDirTest::TearDown();
  }
  InputLimits saved_;
};

void ExpectOneLine(const std::string& message) {
  EXPECT_EQ(message.find('\n'), std::string::npos) << message;
}

TEST_F(InputLimitsTest, AFifoWithoutAWriterIsRefusedNotWaitedFor) {
  const std::string fifo = PathOf("fifo");
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
  const std::string message = ErrorOf([&] { ReadFile(fifo); });
  EXPECT_HAS(message, "'" + fifo + "'");
  EXPECT_HAS(message, "it is a FIFO, not a regular file");
  ExpectOneLine(message);
}

TEST_F(InputLimitsTest, ASymlinkToDevZeroIsRefusedNotReadForever) {
  const std::string link = PathOf("states.csv");
  fs::create_symlink("/dev/zero", link);
  const std::string message = ErrorOf([&] { ReadFile(link); });
  EXPECT_HAS(message, "'" + link + "'");
  EXPECT_HAS(message, "it is a character device, not a regular file");
  ExpectOneLine(message);
}

TEST_F(InputLimitsTest, ADirectoryAndADanglingSymlinkAreNamed) {
  fs::create_directories(dir_ / "d");
  std::string message = ErrorOf([&] { ReadFile(PathOf("d")); });
  EXPECT_HAS(message, "it is a directory, not a regular file");
  fs::create_symlink(dir_ / "nowhere", dir_ / "dangling");
  message = ErrorOf([&] { ReadFile(PathOf("dangling")); });
  EXPECT_HAS(message, "dangling symbolic link");
  ExpectOneLine(message);
}

TEST_F(InputLimitsTest, AFileOverTheSizeLimitIsRefusedAndTheLimitCanBeRaised) {
  const std::string path = Write("big.csv", std::string(1000, 'x'));
  InputLimits limits = saved_;
  limits.max_input_bytes = 999;
  SetInputLimits(limits);
  const std::string message = ErrorOf([&] { ReadFile(path); });
  EXPECT_HAS(message, "1000 bytes, more than the input limit of 999 bytes");
  EXPECT_HAS(message, "SECURE_MAX_INPUT_BYTES");
  ExpectOneLine(message);
  limits.max_input_bytes = 1000;
  SetInputLimits(limits);
  EXPECT_EQ(ReadFile(path).size(), 1000u);
}

TEST_F(InputLimitsTest, TheDefaultLimitsAreTheStatedOnes) {
  const InputLimits defaults;
  EXPECT_EQ(defaults.max_input_bytes, std::uint64_t{4} << 30);
  EXPECT_EQ(defaults.max_config_nodes, 100'000);
  EXPECT_EQ(defaults.max_config_depth, 64);
}

// "Billion laughs": 9 levels of aliases, each a list of 9 of the level below.
std::string AliasBomb(int levels) {
  std::string text = "a0: &a0 [x, x, x, x, x, x, x, x, x]\n";
  for (int k = 1; k <= levels; ++k) {
    const std::string p = "*a" + std::to_string(k - 1);
    text += "a" + std::to_string(k) + ": &a" + std::to_string(k) + " [" + p + ", " + p + ", " +
            p + ", " + p + ", " + p + ", " + p + ", " + p + ", " + p + ", " + p + "]\n";
  }
  return text;
}

TEST_F(InputLimitsTest, AYamlAliasBombStopsAtTheNodeLimit) {
  const YAML::Node root = YAML::Load(AliasBomb(8));
  const std::string message = ErrorOf([&] { CheckYamlLimits(root, "bomb.yaml"); });
  EXPECT_HAS(message, "bomb.yaml: more than 100000 YAML nodes with aliases expanded");
  ExpectOneLine(message);
  // Two levels (about 100 nodes) pass; so does the bomb under a raised limit of its size.
  CheckYamlLimits(YAML::Load(AliasBomb(1)), "small.yaml");
  InputLimits limits = saved_;
  limits.max_config_nodes = 2'000'000;
  SetInputLimits(limits);
  CheckYamlLimits(YAML::Load(AliasBomb(4)), "raised.yaml");
}

TEST_F(InputLimitsTest, DeepYamlIsRefusedBeforeAndAfterParsing) {
  const std::string deep_flow = std::string(100000, '[') + std::string(100000, ']');
  std::string message = ErrorOf([&] { CheckYamlTextDepth(deep_flow, "deep.yaml"); });
  EXPECT_HAS(message, "deep.yaml:1: nested more than 64 levels deep");
  ExpectOneLine(message);
  std::string dashes;
  for (int k = 0; k < 100; ++k) dashes += "- ";
  message = ErrorOf([&] { CheckYamlTextDepth(dashes + "x\n", "dashes.yaml"); });
  EXPECT_HAS(message, "dashes.yaml:1: nested more than 64 levels deep");
  // Brackets in quotes and comments do not count; 64 levels pass.
  CheckYamlTextDepth("a: '[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[' # [[[[\n",
                     "quoted.yaml");
  CheckYamlTextDepth(std::string(63, '[') + std::string(63, ']'), "ok.yaml");
  // Block nesting by indentation: refused by the walk after parsing.
  std::string block;
  for (int k = 0; k < 70; ++k) block += std::string(2 * k, ' ') + "k:\n";
  message = ErrorOf([&] { CheckYamlLimits(YAML::Load(block), "block.yaml"); });
  EXPECT_HAS(message, "nested more than 64 levels deep");
}

}  // namespace
}  // namespace secure
