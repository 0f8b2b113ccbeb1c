#pragma once
// One run at a time per run directory: an advisory lock (flock(2)) on files in the directory,
// held for the run's lifetime and released by the kernel on any exit, a SIGKILL included, so a
// lock left by a killed run never blocks the next one.
//
//   - An unsharded run takes DIR/.secure-lock exclusively and writes its PID there.
//   - Shard k of N takes DIR/.secure-lock shared (shards may share a directory, on one host or
//     on several with a shared filesystem that supports flock) and DIR/.secure-lock-shard-k-of-N
//     exclusively, with its PID.
// A second run into the same directory, an unsharded one beside shards, or the same shard twice
// fails at once: "another run (PID 1234) is writing to DIR (DIR/.secure-lock): wait for it or use
// another --out". The lock files stay (empty of meaning once unlocked); the descriptors are
// close-on-exec, so a child process (ffmpeg) never keeps a lock alive.
#include <string>

namespace secure::experiments {

class RunDirectoryLock {
 public:
  /// Locks `dir` (which must exist) for an unsharded run (shards = 1) or for shard `shard` of
  /// `shards`. @throws secure::Error naming the directory, the lock file and the holder's PID if
  /// another run holds it, or naming the file if it cannot be opened.
  RunDirectoryLock(const std::string& dir, int shard, int shards);
  ~RunDirectoryLock();
  RunDirectoryLock(const RunDirectoryLock&) = delete;
  RunDirectoryLock& operator=(const RunDirectoryLock&) = delete;

 private:
  int run_fd_ = -1;    // DIR/.secure-lock
  int shard_fd_ = -1;  // DIR/.secure-lock-shard-k-of-N (shards > 1)
};

/// The lock file names, relative to the run directory.
inline constexpr const char* kRunLockFile = ".secure-lock";
std::string ShardLockFile(int shard, int shards);

}  // namespace secure::experiments
