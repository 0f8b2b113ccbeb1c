#pragma once
// A lock on a run directory (issue 34): two runs writing one --out would overwrite each other's
// models, task files and result.json and both exit 0. A run holds an advisory flock on
// "<dir>/.lock" (holding its PID) for as long as it lives, and removes the file as it ends; the
// kernel releases the lock on any exit, SIGKILL included, so the file a killed run leaves behind
// never blocks. A second run fails at
// once naming the holder's PID. Shards of one experiment share the directory: each holds a
// shared lock on .lock (an unsharded run or a merge, which need the directory alone, then fail)
// and its own exclusive ".lock-shard-<k>-of-<n>" (the same shard twice fails).

#include <string>

namespace secure {

class RunDirectoryLock {
 public:
  /// Takes the lock of `dir` (which must exist): exclusive, or for shard `shard` of `shards`
  /// (shards > 1) the shared lock plus the shard's own. `what` names the run in the message.
  /// @throws secure::Error "run directory 'd' is in use by another run (process 1234, holding
  ///   d/.lock): wait for it to end, or write to another --out".
  explicit RunDirectoryLock(const std::string& dir, int shard = 0, int shards = 1);
  ~RunDirectoryLock();
  RunDirectoryLock(const RunDirectoryLock&) = delete;
  RunDirectoryLock& operator=(const RunDirectoryLock&) = delete;

 private:
  std::string path_, shard_path_;
  bool exclusive_ = false;
  int fd_ = -1;
  int shard_fd_ = -1;
};

}  // namespace secure
