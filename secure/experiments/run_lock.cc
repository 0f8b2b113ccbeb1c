#include "secure/experiments/run_lock.h"

#include <fcntl.h>
#include <sys/file.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <string>
#include <vector>

#include "secure/common/error.h"

namespace secure::experiments {
namespace {

int OpenLockFile(const std::string& path) {
  const int fd = ::open(path.c_str(), O_RDWR | O_CREAT | O_CLOEXEC | O_NOFOLLOW, 0644);
  SECURE_CHECK(fd >= 0, "cannot open the run directory's lock file " << path << ": "
                                                                     << std::strerror(errno));
  return fd;
}

// The PID written in a lock file, or "unknown".
std::string HolderOf(const std::string& path) {
  char buffer[32] = {};
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC | O_NOFOLLOW);
  if (fd < 0) return "unknown";
  const ssize_t n = ::read(fd, buffer, sizeof buffer - 1);
  ::close(fd);
  std::string pid(buffer, n > 0 ? static_cast<std::size_t>(n) : 0);
  while (!pid.empty() && (pid.back() == '\n' || pid.back() == ' ')) pid.pop_back();
  return pid.empty() ? "unknown" : pid;
}

void WritePid(int fd) {
  const std::string pid = std::to_string(::getpid()) + "\n";
  if (::ftruncate(fd, 0) == 0) {
    [[maybe_unused]] const ssize_t n = ::pwrite(fd, pid.data(), pid.size(), 0);
  }
}

// "shard 0/2 (PID 12), shard 1/2 (PID 13)": the shard lock files of `dir` held now.
std::string HeldShards(const std::string& dir) {
  std::string held;
  std::error_code ec;
  for (const auto& entry : std::filesystem::directory_iterator(dir, ec)) {
    const std::string name = entry.path().filename().string();
    const std::string prefix = std::string(kRunLockFile) + "-shard-";
    if (name.rfind(prefix, 0) != 0) continue;
    const int fd = ::open(entry.path().c_str(), O_RDONLY | O_CLOEXEC | O_NOFOLLOW);
    if (fd < 0) continue;
    const bool locked = ::flock(fd, LOCK_SH | LOCK_NB) != 0 && errno == EWOULDBLOCK;
    ::close(fd);
    if (!locked) continue;
    std::string which = name.substr(prefix.size());  // "k-of-N"
    const auto of = which.find("-of-");
    if (of != std::string::npos) which = which.substr(0, of) + "/" + which.substr(of + 4);
    held += (held.empty() ? "" : ", ") + std::string("shard ") + which + " (PID " +
            HolderOf(entry.path().string()) + ")";
  }
  return held.empty() ? "a run" : held;
}

}  // namespace

std::string ShardLockFile(int shard, int shards) {
  return std::string(kRunLockFile) + "-shard-" + std::to_string(shard) + "-of-" +
         std::to_string(shards);
}

RunDirectoryLock::RunDirectoryLock(const std::string& dir, int shard, int shards) {
  SECURE_CHECK(shards >= 1 && shard >= 0 && shard < shards,
               "RunDirectoryLock: shard " << shard << " of " << shards);
  const std::string run_path = dir + "/" + kRunLockFile;
  run_fd_ = OpenLockFile(run_path);
  if (shards == 1) {
    if (::flock(run_fd_, LOCK_EX | LOCK_NB) != 0) {
      ::close(run_fd_);
      run_fd_ = -1;
      // Held exclusively by another unsharded run (its PID in the file), or shared by shards.
      const std::string shards_held = HeldShards(dir);
      SECURE_THROW("another run is writing to " << dir << " ("
                                                << (shards_held == "a run"
                                                        ? "PID " + HolderOf(run_path)
                                                        : shards_held)
                                                << ", lock " << run_path
                                                << "): wait for it to end or use another --out");
    }
    WritePid(run_fd_);
    return;
  }
  if (::flock(run_fd_, LOCK_SH | LOCK_NB) != 0) {
    ::close(run_fd_);
    run_fd_ = -1;
    SECURE_THROW("another run is writing to " << dir << " (an unsharded run, PID "
                                              << HolderOf(run_path) << ", lock " << run_path
                                              << "): wait for it to end or use another --out");
  }
  const std::string shard_path = dir + "/" + ShardLockFile(shard, shards);
  shard_fd_ = OpenLockFile(shard_path);
  if (::flock(shard_fd_, LOCK_EX | LOCK_NB) != 0) {
    ::close(shard_fd_);
    ::close(run_fd_);
    shard_fd_ = run_fd_ = -1;
    SECURE_THROW("shard " << shard << "/" << shards << " is already running into " << dir
                          << " (PID " << HolderOf(shard_path) << ", lock " << shard_path
                          << "): wait for it to end");
  }
  WritePid(shard_fd_);
}

RunDirectoryLock::~RunDirectoryLock() {
  if (shard_fd_ >= 0) ::close(shard_fd_);
  if (run_fd_ >= 0) ::close(run_fd_);
}

}  // namespace secure::experiments
