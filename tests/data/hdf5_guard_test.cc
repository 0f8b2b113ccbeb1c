// The HDF5 readers' guard (secure/data/hdf5_guard.cc, issue 34): files are read in a child
// process with a memory limit, so libhdf5's own defects on malformed files (the hdf5_fuzz
// findings, now regression inputs in tests/fuzz/corpus/hdf5_fuzz/) are one secure::Error naming
// the file, and the data read through the guard are those read in this process.
#include <signal.h>
#include <sys/prctl.h>
#include <unistd.h>

#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <Eigen/Core>

#include "secure/common/error.h"
#include "secure/common/input_limits.h"
#include "secure/data/data.h"
#include "tests/data/hdf5_test_file.h"
#include "tests/test_util.h"

namespace secure::data {
namespace {

using secure::test::ErrorOf;
using secure::test::Hdf5TestFile;

class Hdf5GuardTest : public secure::test::TempDirTest {
 protected:
  void TearDown() override {
    SetInputLimits(saved_);
    TempDirTest::TearDown();
  }
  const InputLimits saved_ = GetInputLimits();
};

void ExpectOneLineNaming(const std::string& message, const std::string& path) {
  EXPECT_NE(message.find(path), std::string::npos) << message;
  EXPECT_EQ(message.find('\n'), std::string::npos) << "not one line: " << message;
  EXPECT_FALSE(message.empty());
}

// A robomimic-style file of `rows` steps in 2 demos, written by our writer.
TrajectorySet Demos(long rows) {
  TrajectorySet set;
  set.state_features = {"x", "v"};
  set.action_features = {"a"};
  set.states = Eigen::MatrixXf::Random(2, rows);
  set.actions = Eigen::MatrixXf::Random(1, rows);
  set.episode_begin = {0, rows / 2, rows};
  return set;
}

// The three files on which libhdf5 1.10.8 crashed (SEGV in H5F__accum_read) or allocated
// 2.3-2.6 GB (H5Dread): each is one error naming the file (the states alone may be intact, as may the first demo).
TEST_F(Hdf5GuardTest, TheLibhdf5FindingsAreOneLineErrors) {
  const std::filesystem::path corpus =
      std::filesystem::path(SECURE_SOURCE_DIR) / "tests/fuzz/corpus/hdf5_fuzz";
  int found = 0;
  for (const char* name :
       {"oom-libhdf5-H5Dread-a", "oom-libhdf5-H5Dread-b", "segv-libhdf5-H5F__accum_read"}) {
    const std::string path = PathOf(std::string(name) + ".h5");
    std::filesystem::copy_file(corpus / name, path);
    ++found;
    SCOPED_TRACE(name);
    ExpectOneLineNaming(ErrorOf([&] { ReadTrajectories(path, {}, {}); }), path);
    // The states alone, or the first demo's shapes, may be intact: read, or one error.
    try {
      EXPECT_GT(ReadStateSet(path, {}).size(), 0);
    } catch (const Error& e) {
      ExpectOneLineNaming(e.what(), path);
    }
    try {
      EXPECT_TRUE(InspectHdf5(path).has_demonstrations);
    } catch (const Error& e) {
      ExpectOneLineNaming(e.what(), path);
    }
  }
  EXPECT_EQ(found, 3);
}

// The oversized float type of the H5Dread findings is refused before libhdf5 converts it.
TEST_F(Hdf5GuardTest, AFloatTypeThatIsNoIeeeFloatIsRefusedByName) {
  const std::string path = PathOf("oom.h5");
  std::filesystem::copy_file(
      std::filesystem::path(SECURE_SOURCE_DIR) / "tests/fuzz/corpus/hdf5_fuzz/oom-libhdf5-H5Dread-a",
      path);
  const std::string message = ErrorOf([&] { ReadTrajectories(path, {}, {}); });
  EXPECT_NE(message.find("expected IEEE float32 or float64"), std::string::npos) << message;
}

TEST_F(Hdf5GuardTest, TheGuardReturnsWhatTheReaderReadsInThisProcess) {
  const std::string path = PathOf("demos.h5");
  WriteTrajectories(path, Demos(50));
  const TrajectorySet guarded = ReadTrajectories(path, {}, {});
  const TrajectorySet here = internal::ReadHdf5TrajectoriesInProcess(path, {}, {});
  EXPECT_EQ(guarded.source, path);
  EXPECT_EQ(guarded.state_features, here.state_features);
  EXPECT_EQ(guarded.action_features, here.action_features);
  EXPECT_EQ(guarded.episode_begin, here.episode_begin);
  EXPECT_EQ(guarded.states, here.states);  // one path reproducing itself: bit for bit
  EXPECT_EQ(guarded.actions, here.actions);
  const StateSet states = ReadStateSet(path, {"v"});
  EXPECT_EQ(states.features, std::vector<std::string>{"v"});
  EXPECT_EQ(states.states, here.states.row(1));
  const Hdf5Contents c = InspectHdf5(path);
  EXPECT_TRUE(c.has_demonstrations);
  EXPECT_EQ(c.observation_features, internal::InspectHdf5InProcess(path).observation_features);
}

TEST_F(Hdf5GuardTest, TheReadersErrorsComeThroughUnchanged) {
  const std::string path = PathOf("demos.h5");
  WriteTrajectories(path, Demos(10));
  const std::string guarded = ErrorOf([&] { ReadTrajectories(path, {"nope"}, {}); });
  const std::string here =
      ErrorOf([&] { internal::ReadHdf5TrajectoriesInProcess(path, {"nope"}, {}); });
  EXPECT_EQ(guarded, here);
  EXPECT_NE(guarded.find("no key or column 'nope'"), std::string::npos) << guarded;
  // Refused before a child starts: no file, a directory.
  ExpectOneLineNaming(ErrorOf([&] { ReadTrajectories(PathOf("missing.h5"), {}, {}); }),
                      PathOf("missing.h5"));
  std::filesystem::create_directories(PathOf("dir.h5"));
  EXPECT_NE(ErrorOf([&] { ReadStateSet(PathOf("dir.h5"), {}); }).find("directory"),
            std::string::npos);
}

TEST_F(Hdf5GuardTest, TheMemoryLimitIsStatedOverridableAndNamedWhenHit) {
  EXPECT_EQ(InputLimits().max_hdf5_memory_bytes, 0u);  // the default: the formula below
  InputLimits limits = saved_;
  limits.max_hdf5_memory_bytes = 0;
  SetInputLimits(limits);
  EXPECT_EQ(Hdf5ReaderMemoryLimit(1000), (std::uint64_t{1} << 30) + 8000);
  const std::string path = PathOf("big.h5");
  WriteTrajectories(path, Demos(40'000));
  ASSERT_GT(std::filesystem::file_size(path), 1u << 20);
  limits.max_hdf5_memory_bytes = 1 << 20;  // less than the file's own image
  SetInputLimits(limits);
  EXPECT_EQ(Hdf5ReaderMemoryLimit(1000), 1u << 20);
  const std::string message = ErrorOf([&] { ReadTrajectories(path, {}, {}); });
  ExpectOneLineNaming(message, path);
  EXPECT_NE(message.find("memory limit of 1048576 bytes"), std::string::npos) << message;
  EXPECT_NE(message.find("SECURE_MAX_HDF5_MEMORY"), std::string::npos) << message;
  limits.max_hdf5_memory_bytes = 0;
  SetInputLimits(limits);
  EXPECT_EQ(ReadTrajectories(path, {}, {}).num_steps(), 40'000);
}

// A child that never answers (libhdf5 in a loop on a malformed file, or stuck in a lock another
// thread held at fork) is killed at the time limit, and the error names the file and the limit.
TEST_F(Hdf5GuardTest, AChildThatTakesTooLongIsStoppedAtTheTimeLimit) {
  EXPECT_EQ(InputLimits().max_hdf5_seconds, 600u);
  const std::string path = Write("slow.h5", "not read");
  InputLimits limits = saved_;
  limits.max_hdf5_seconds = 1;
  SetInputLimits(limits);
  std::string pid_file = PathOf("child.pid");
  const auto t0 = std::chrono::steady_clock::now();
  const std::string message = ErrorOf([&] {
    internal::RunInHdf5ReaderProcess(path, [&](std::string*) {
      std::ofstream(pid_file) << ::getpid();
      ::sleep(120);
    });
  });
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  EXPECT_GE(seconds, 1.0);
  EXPECT_LT(seconds, 60.0);
  ExpectOneLineNaming(message, path);
  EXPECT_HAS(message, "took longer than 1 s");
  EXPECT_HAS(message, "SECURE_MAX_HDF5_SECONDS");
  std::string pid;
  std::ifstream(pid_file) >> pid;
  ASSERT_FALSE(pid.empty());
  EXPECT_FALSE(std::filesystem::exists("/proc/" + pid)) << "the child " << pid << " still runs";
  // A child that answers in time is not affected by the limit.
  EXPECT_EQ(internal::RunInHdf5ReaderProcess(path, [](std::string* out) { *out += "ok"; }), "ok");
}

// A process the reader's child starts (a sanitizer's symbolizer, say) may keep the reply's pipe
// open after the child has died. The parent does not wait for it: the child's reply, or its
// death, comes back as soon as the child is gone, and the straggler is killed with the child's
// process group. (Without this, each call below took the grandchild's 120 s.)
TEST_F(Hdf5GuardTest, AProcessTheChildStartedDoesNotHoldUpTheReply) {
  const std::string path = Write("any.h5", "not read");
  // Starts a grandchild that inherits the pipe and sleeps for 120 s; returns its pid.
  const auto start_straggler = [] {
    const pid_t pid = ::fork();
    if (pid == 0) {
      ::sleep(120);
      ::_exit(0);
    }
    return pid;
  };
  // Whether `pid` is gone or dead (a zombie, until whoever adopted it reaps it).
  const auto gone = [](const std::string& pid) {
    std::ifstream stat("/proc/" + pid + "/stat");
    std::string id, name, state;
    if (!(stat >> id >> name >> state)) return true;
    return state == "Z" || state == "X";
  };
  const auto t0 = std::chrono::steady_clock::now();
  const std::string reply = internal::RunInHdf5ReaderProcess(
      path, [&](std::string* out) { *out += std::to_string(start_straggler()); });
  ASSERT_FALSE(reply.empty());
  const std::string crash = ErrorOf([&] {
    internal::RunInHdf5ReaderProcess(path, [&](std::string*) {
      start_straggler();
      ::raise(SIGABRT);
    });
  });
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  EXPECT_LT(seconds, 60.0) << "the parent waited for the grandchildren";
  EXPECT_HAS(crash, "crashed reading the file (signal 6, SIGABRT)");
  ExpectOneLineNaming(crash, path);
  for (int i = 0; i < 100 && !gone(reply); ++i) ::usleep(10'000);
  EXPECT_TRUE(gone(reply)) << "grandchild " << reply << " still runs";
}

// The reader's child is never dumped: a core_pattern that pipes to a helper (systemd-coredump,
// apport) ignores RLIMIT_CORE, and the dump of a crashed child would hold up the reply.
TEST_F(Hdf5GuardTest, TheChildIsNotDumpable) {
  const std::string path = Write("any.h5", "not read");
  EXPECT_EQ(internal::RunInHdf5ReaderProcess(path, [](std::string* out) {
              *out += std::to_string(::prctl(PR_GET_DUMPABLE, 0, 0, 0, 0));
            }),
            "0");
}

}  // namespace
}  // namespace secure::data
