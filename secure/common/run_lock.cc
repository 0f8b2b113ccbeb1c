#include "secure/common/run_lock.h"

#include <fcntl.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <string>

#include "secure/common/error.h"

namespace secure {
namespace {

// The holder's PID as the lock file records it ("" if unknown).
std::string HolderOf(int fd) {
  char buffer[32] = {};
  const ssize_t n = ::pread(fd, buffer, sizeof buffer - 1, 0);
  std::string text(buffer, n > 0 ? static_cast<std::size_t>(n) : 0);
  while (!text.empty() && (text.back() == '\n' || text.back() == ' ')) text.pop_back();
  return text;
}

// Opens `path` and takes `operation` (LOCK_EX or LOCK_SH) without waiting; records our PID.
// Returns the descriptor.
int TakeOnce(const std::string& dir, const std::string& path, int operation);

// TakeOnce until the locked file is the one at `path` (an exclusive holder unlinks the file as
// it ends: a lock taken on the unlinked file would guard nothing).
int Take(const std::string& dir, const std::string& path, int operation) {
  for (int attempt = 0;; ++attempt) {
    const int fd = TakeOnce(dir, path, operation);
    struct stat held {}, named {};
    if (::fstat(fd, &held) == 0 && ::stat(path.c_str(), &named) == 0 &&
        held.st_dev == named.st_dev && held.st_ino == named.st_ino)
      return fd;
    ::close(fd);
    SECURE_CHECK(attempt < 100, "cannot lock run directory '" << dir << "': " << path
                                                              << " keeps being replaced");
  }
}

int TakeOnce(const std::string& dir, const std::string& path, int operation) {
  const int fd = ::open(path.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0666);
  SECURE_CHECK(fd >= 0, "cannot lock run directory '" << dir << "': cannot open '" << path
                                                      << "': " << std::strerror(errno));
  if (::flock(fd, operation | LOCK_NB) != 0) {
    const int error = errno;
    const std::string holder = HolderOf(fd);
    ::close(fd);
    SECURE_CHECK(error == EWOULDBLOCK, "cannot lock run directory '" << dir << "': " << path
                                                                     << ": "
                                                                     << std::strerror(error));
    SECURE_THROW("run directory '" << dir << "' is in use by another run ("
                                   << (holder.empty() ? std::string("a process")
                                                      : "process " + holder)
                                   << ", holding " << path
                                   << "): wait for it to end, or write to another --out");
  }
  // Our PID, for the message of the next run (a shared holder records itself too: one of them).
  const std::string pid = std::to_string(::getpid()) + "\n";
  if (::ftruncate(fd, 0) == 0) {
    [[maybe_unused]] const ssize_t n = ::pwrite(fd, pid.data(), pid.size(), 0);
  }
  return fd;
}

}  // namespace

RunDirectoryLock::RunDirectoryLock(const std::string& dir, int shard, int shards) {
  const std::string base = (dir.empty() ? std::string(".") : dir) + "/.lock";
  path_ = base;
  if (shards <= 1) {
    fd_ = Take(dir, base, LOCK_EX);
    exclusive_ = true;
    return;
  }
  fd_ = Take(dir, base, LOCK_SH);
  try {
    shard_path_ = base + "-shard-" + std::to_string(shard) + "-of-" + std::to_string(shards);
    shard_fd_ = Take(dir, shard_path_, LOCK_EX);
  } catch (...) {
    ::close(fd_);
    throw;
  }
}

RunDirectoryLock::~RunDirectoryLock() {
  // An exclusive holder removes its lock file (a finished run leaves none; a killed one leaves
  // a file no process holds, which does not block): unlinked while still locked, so no other run
  // can hold the old file meanwhile. Shards' shared .lock stays (others may hold it).
  if (shard_fd_ >= 0) {
    ::unlink(shard_path_.c_str());
    ::close(shard_fd_);
  }
  if (fd_ >= 0) {
    if (exclusive_) ::unlink(path_.c_str());
    ::close(fd_);
  }
}

}  // namespace secure
