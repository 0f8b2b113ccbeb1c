#include "secure/common/atomic_file.h"
#include "tests/test_util.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "secure/common/error.h"

namespace secure {
namespace {

namespace fs = std::filesystem;

using secure::test::ErrorOf;

// A fresh empty directory per test, removed afterwards.
class AtomicFileTest : public ::testing::Test {
 protected:
  void SetUp() override {
    static std::atomic<int> counter{0};
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    dir_ = fs::path(::testing::TempDir()) / ("secure_atomic_file_" + std::to_string(::getpid()) +
                                             "_" + info->name() + "_" + std::to_string(counter++));
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override {
    std::error_code ec;
    fs::remove_all(dir_, ec);
  }

  std::vector<std::string> Entries() const {
    std::vector<std::string> names;
    for (const auto& entry : fs::directory_iterator(dir_))
      names.push_back(entry.path().filename().string());
    return names;
  }

  fs::path dir_;
};

TEST_F(AtomicFileTest, WriteThenReadReturnsTheBytes) {
  const std::string path = (dir_ / "a.txt").string();
  WriteFileAtomically(path, "hello\nworld");
  EXPECT_EQ(ReadFile(path), "hello\nworld");
}

TEST_F(AtomicFileTest, RoundTripsBinaryContentWithNulBytes) {
  std::string bytes;
  for (int i = 0; i < 256; ++i) bytes.push_back(static_cast<char>(i));
  bytes += std::string(3, '\0') + "\r\n\x1a";
  const std::string path = (dir_ / "bin").string();
  WriteFileAtomically(path, bytes);
  EXPECT_EQ(ReadFile(path), bytes);
  EXPECT_EQ(fs::file_size(path), bytes.size());
}

TEST_F(AtomicFileTest, RoundTripsAnEmptyFile) {
  const std::string path = (dir_ / "empty").string();
  WriteFileAtomically(path, "");
  EXPECT_TRUE(fs::exists(path));
  EXPECT_EQ(ReadFile(path), "");
}

TEST_F(AtomicFileTest, RoundTripsALargeFile) {
  std::string bytes(5 * 1000 * 1000 + 17, '\0');
  for (std::size_t i = 0; i < bytes.size(); ++i) bytes[i] = static_cast<char>((i * 131) % 251);
  const std::string path = (dir_ / "large").string();
  WriteFileAtomically(path, bytes);
  EXPECT_TRUE(ReadFile(path) == bytes);
}

TEST_F(AtomicFileTest, OverwriteReplacesTheWholeContent) {
  const std::string path = (dir_ / "a.txt").string();
  WriteFileAtomically(path, "a long first version of the file");
  WriteFileAtomically(path, "short");
  EXPECT_EQ(ReadFile(path), "short");  // no tail of the longer first version
}

TEST_F(AtomicFileTest, WriteLeavesNoTemporaryFilesBehind) {
  const std::string path = (dir_ / "model.json").string();
  WriteFileAtomically(path, "1");
  WriteFileAtomically(path, "2");
  WriteFileAtomically((dir_ / "other").string(), "3");
  auto names = Entries();
  std::sort(names.begin(), names.end());
  EXPECT_EQ(names, (std::vector<std::string>{"model.json", "other"}));
}

TEST_F(AtomicFileTest, WriteIntoAMissingDirectoryThrowsNamingThePath) {
  const std::string path = (dir_ / "no_such_dir" / "file.txt").string();
  const std::string message = ErrorOf([&] { WriteFileAtomically(path, "x"); });
  EXPECT_HAS(message, path);
  EXPECT_FALSE(fs::exists(dir_ / "no_such_dir"));
  EXPECT_TRUE(Entries().empty());
}

TEST_F(AtomicFileTest, FailedWriteLeavesThePreviousFileAndNoTemporaries) {
  // Renaming a file over a non-empty directory fails after the temporary was written: the
  // temporary must be removed and the directory left intact.
  const fs::path target = dir_ / "occupied";
  fs::create_directories(target);
  WriteFileAtomically((target / "keep").string(), "kept");
  const std::string message = ErrorOf([&] { WriteFileAtomically(target.string(), "new"); });
  EXPECT_HAS(message, target.string());
  EXPECT_TRUE(fs::is_directory(target));
  EXPECT_EQ(ReadFile((target / "keep").string()), "kept");
  EXPECT_EQ(Entries(), std::vector<std::string>{"occupied"});
}

TEST_F(AtomicFileTest, ReadOfAMissingFileThrowsNamingThePath) {
  const std::string path = (dir_ / "missing.bin").string();
  const std::string message = ErrorOf([&] { ReadFile(path); });
  EXPECT_HAS(message, path);
}

TEST_F(AtomicFileTest, WrittenFileIsReadableByStandardStreams) {
  const std::string path = (dir_ / "plain.txt").string();
  WriteFileAtomically(path, "line 1\nline 2\n");
  std::ifstream in(path);
  std::string line1, line2;
  std::getline(in, line1);
  std::getline(in, line2);
  EXPECT_EQ(line1, "line 1");
  EXPECT_EQ(line2, "line 2");
}

}  // namespace
}  // namespace secure
