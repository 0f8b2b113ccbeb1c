// One run at a time per run directory (RunDirectoryLock): a second run fails at once naming the
// holder's PID, shards share a directory but not a shard, and a SIGKILLed holder's lock is gone.
#include "secure/experiments/run_lock.h"

#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <fstream>
#include <string>

#include "tests/test_util.h"

namespace secure::experiments {
namespace {

using test::ErrorOf;

class RunLockTest : public test::TempDirTest {
 protected:
  std::string dir() const { return dir_.string(); }
};

TEST_F(RunLockTest, ASecondRunFailsNamingTheHolder) {
  const std::string pid = std::to_string(::getpid());
  {
    const RunDirectoryLock first(dir(), 0, 1);
    const std::string e = ErrorOf([&] { RunDirectoryLock second(dir(), 0, 1); });
    EXPECT_HAS(e, "another run is writing to " + dir());
    EXPECT_HAS(e, "PID " + pid);
    EXPECT_HAS(e, "use another --out");
    // A shard beside an unsharded run is refused too.
    EXPECT_HAS(ErrorOf([&] { RunDirectoryLock shard(dir(), 1, 2); }),
               "an unsharded run, PID " + pid);
  }
  // Released with the first: the next run takes it.
  const RunDirectoryLock again(dir(), 0, 1);
}

TEST_F(RunLockTest, ShardsShareADirectoryButNotAShard) {
  const std::string pid = std::to_string(::getpid());
  const RunDirectoryLock zero(dir(), 0, 2), one(dir(), 1, 2);
  EXPECT_HAS(ErrorOf([&] { RunDirectoryLock twice(dir(), 1, 2); }),
             "shard 1/2 is already running into " + dir() + " (PID " + pid);
  const std::string e = ErrorOf([&] { RunDirectoryLock unsharded(dir(), 0, 1); });
  EXPECT_HAS(e, "shard 0/2 (PID " + pid + ")");
  EXPECT_HAS(e, "shard 1/2 (PID " + pid + ")");
}

TEST_F(RunLockTest, AKilledHolderLeavesNoLock) {
  const pid_t child = ::fork();
  ASSERT_GE(child, 0);
  if (child == 0) {
    const RunDirectoryLock held(dir(), 0, 1);
    ::kill(::getpid(), SIGKILL);  // no destructor runs
    ::_exit(0);
  }
  int status = 0;
  ASSERT_EQ(::waitpid(child, &status, 0), child);
  ASSERT_TRUE(WIFSIGNALED(status) && WTERMSIG(status) == SIGKILL);
  std::ifstream file(dir() + "/" + kRunLockFile);
  std::string recorded;
  file >> recorded;
  EXPECT_EQ(recorded, std::to_string(child));  // the dead holder's PID is still written there
  const RunDirectoryLock next(dir(), 0, 1);     // and does not block
}

TEST_F(RunLockTest, AMissingDirectoryIsAnErrorNamingTheFile) {
  EXPECT_HAS(ErrorOf([&] { RunDirectoryLock l(dir() + "/missing", 0, 1); }),
             dir() + "/missing/" + kRunLockFile);
}

}  // namespace
}  // namespace secure::experiments
