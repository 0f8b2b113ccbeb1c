#include "secure/common/atomic_file.h"
#include "secure/common/input_limits.h"

#include <dirent.h>
#include <fcntl.h>
#include <signal.h>
#include <sys/stat.h>
#include <sys/types.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <climits>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <mutex>
#include <sstream>
#include <vector>

#include "secure/common/error.h"

namespace secure {
namespace {

// ---------------------------------------------------------------------------------------------
// The registry of temporaries being written, read by the signal handler. Fixed size, no
// allocation, lock-free atomics only. A slot is kFree, kClaimed (a writer is filling in the
// path), kActive (the path is complete and may exist on disk) or kCleaning (a signal handler is
// unlinking it). A write whose path does not fit or that finds no free slot is simply not
// registered: the stale-temporary sweep of a later write still removes it.
constexpr int kSlots = 64;
constexpr std::size_t kSlotPathBytes = PATH_MAX;
enum SlotState : int { kFree = 0, kClaimed = 1, kActive = 2, kCleaning = 3 };

struct Slot {
  std::atomic<int> state{kFree};
  char path[kSlotPathBytes];
};
static_assert(std::atomic<int>::is_always_lock_free, "the signal handler needs lock-free atomics");

Slot g_slots[kSlots];

int RegisterTemporary(const std::string& path) {
  if (path.size() >= kSlotPathBytes) return -1;
  for (int i = 0; i < kSlots; ++i) {
    int expected = kFree;
    if (!g_slots[i].state.compare_exchange_strong(expected, kClaimed, std::memory_order_acquire))
      continue;
    std::memcpy(g_slots[i].path, path.c_str(), path.size() + 1);
    g_slots[i].state.store(kActive, std::memory_order_release);
    return i;
  }
  return -1;
}

void UnregisterTemporary(int slot) {
  if (slot < 0) return;
  // Wait while a signal handler in another thread is unlinking this slot's path (it then
  // re-raises a fatal signal, or, called by an embedder, puts the slot back to kActive).
  for (;;) {
    int expected = kActive;
    if (g_slots[slot].state.compare_exchange_weak(expected, kFree, std::memory_order_acq_rel))
      return;
  }
}

// The temporary of one write: registered from before it is created until it is renamed or
// removed; removed by the destructor unless committed (renamed).
class PendingTemporary {
 public:
  explicit PendingTemporary(std::string path) : path_(std::move(path)) {
    slot_ = RegisterTemporary(path_);
  }
  ~PendingTemporary() {
    if (created_ && !committed_) ::unlink(path_.c_str());
    UnregisterTemporary(slot_);
  }
  PendingTemporary(const PendingTemporary&) = delete;
  PendingTemporary& operator=(const PendingTemporary&) = delete;

  const std::string& path() const { return path_; }
  void MarkCreated() { created_ = true; }
  void Commit() { committed_ = true; }

 private:
  std::string path_;
  int slot_ = -1;
  bool created_ = false;
  bool committed_ = false;
};

extern "C" void CleanupTemporariesOnSignal(int sig) {
  const int saved_errno = errno;
  RemovePendingTemporaryFiles();
  // Die of the same signal, so the exit status still says "killed by SIGINT/SIGTERM". The signal
  // is blocked while this handler runs; it is delivered (with the default action) on return.
  struct sigaction dfl {};
  dfl.sa_handler = SIG_DFL;
  sigemptyset(&dfl.sa_mask);
  ::sigaction(sig, &dfl, nullptr);
  ::raise(sig);
  errno = saved_errno;
}

// ---------------------------------------------------------------------------------------------
// Paths and messages.

// "dir/" for "dir/name", "/" for "/name", "" for "name".
std::string DirPart(const std::string& path) {
  const std::size_t slash = path.rfind('/');
  return slash == std::string::npos ? std::string() : path.substr(0, slash + 1);
}

// How messages name the output: the path given, plus the target when it is reached through a
// symbolic link.
std::string Shown(const std::string& path, const std::string& target) {
  std::string s = "'" + path + "'";
  if (target != path) s += " (symbolic link to '" + target + "')";
  return s;
}

std::string TypeName(mode_t mode) {
  if (S_ISDIR(mode)) return "a directory";
  if (S_ISSOCK(mode)) return "a socket";
  if (S_ISBLK(mode)) return "a block device";
  if (S_ISCHR(mode)) return "a character device";
  if (S_ISFIFO(mode)) return "a FIFO";
  if (S_ISLNK(mode)) return "a symbolic link";
  if (S_ISREG(mode)) return "a regular file";
  char buf[64];
  std::snprintf(buf, sizeof buf, "a file of unknown type (mode 0%o)", static_cast<unsigned>(mode));
  return buf;
}

std::string ReadLink(const std::string& link, const std::string& path) {
  std::vector<char> buf(256);
  for (;;) {
    const ssize_t n = ::readlink(link.c_str(), buf.data(), buf.size());
    SECURE_CHECK(n >= 0, "cannot write " << Shown(path, link) << ": cannot read the symbolic link: "
                                         << std::strerror(errno));
    if (static_cast<std::size_t>(n) < buf.size()) return std::string(buf.data(), n);
    buf.resize(buf.size() * 2);
  }
}

// Follows the chain of symbolic links starting at `path` (relative links against the directory
// of the link that holds them) to the first name that is not a link, which may not exist.
std::string ResolveLinks(const std::string& path) {
  std::string current = path;
  for (int hops = 0;; ++hops) {
    struct stat st {};
    if (::lstat(current.c_str(), &st) != 0) {
      SECURE_CHECK(errno == ENOENT,
                   "cannot write " << Shown(path, current) << ": " << std::strerror(errno));
      return current;
    }
    if (!S_ISLNK(st.st_mode)) return current;
    SECURE_CHECK(hops < 40, "cannot write '" << path << "': too many levels of symbolic links");
    std::string next = ReadLink(current, path);
    SECURE_CHECK(!next.empty(), "cannot write " << Shown(path, current) << ": empty symbolic link");
    if (next[0] != '/') next = DirPart(current) + next;
    current = std::move(next);
  }
}

void WriteAll(int fd, std::string_view bytes, const std::string& shown) {
  const char* data = bytes.data();
  std::size_t left = bytes.size();
  while (left > 0) {
    const ssize_t n = ::write(fd, data, left);
    if (n < 0 && errno == EINTR) continue;
    if (n < 0 && errno == EPIPE)
      SECURE_THROW("cannot write " << shown << ": the reader closed it before all " << bytes.size()
                                   << " bytes were written");
    SECURE_CHECK(
        n > 0, "cannot write " << shown << ": " << (n == 0 ? "no progress" : std::strerror(errno)));
    data += n;
    left -= static_cast<std::size_t>(n);
  }
}

class FdCloser {
 public:
  explicit FdCloser(int fd) : fd_(fd) {}
  ~FdCloser() {
    if (fd_ >= 0) ::close(fd_);
  }
  FdCloser(const FdCloser&) = delete;
  FdCloser& operator=(const FdCloser&) = delete;
  /// Closes now and returns close()'s result (errno set on failure).
  int Close() {
    const int fd = fd_;
    fd_ = -1;
    return ::close(fd);
  }

 private:
  int fd_;
};

// Blocks SIGPIPE in this thread while writing to a FIFO, so a reader that goes away is an EPIPE
// error instead of killing the process; a SIGPIPE raised by our write is consumed.
class SigpipeBlocker {
 public:
  SigpipeBlocker() {
    sigemptyset(&pipe_);
    sigaddset(&pipe_, SIGPIPE);
    sigset_t pending;
    sigpending(&pending);
    was_pending_ = sigismember(&pending, SIGPIPE) == 1;
    pthread_sigmask(SIG_BLOCK, &pipe_, &old_);
  }
  ~SigpipeBlocker() {
    if (!was_pending_) {
      sigset_t pending;
      sigpending(&pending);
      if (sigismember(&pending, SIGPIPE) == 1) {
        const timespec zero{0, 0};
        while (sigtimedwait(&pipe_, nullptr, &zero) < 0 && errno == EINTR) {
        }
      }
    }
    pthread_sigmask(SIG_SETMASK, &old_, nullptr);
  }
  SigpipeBlocker(const SigpipeBlocker&) = delete;
  SigpipeBlocker& operator=(const SigpipeBlocker&) = delete;

 private:
  sigset_t pipe_{};
  sigset_t old_{};
  bool was_pending_ = false;
};

// ---------------------------------------------------------------------------------------------
// The three ways of writing.

// A character device or a FIFO: written in place, never replaced.
void WriteDirect(const std::string& path, const std::string& shown, mode_t mode,
                 std::string_view bytes) {
  const bool fifo = S_ISFIFO(mode);
  const int fd = ::open(path.c_str(), O_WRONLY | O_NOCTTY | O_CLOEXEC | (fifo ? O_NONBLOCK : 0));
  if (fd < 0) {
    SECURE_CHECK(!(fifo && errno == ENXIO),
                 "cannot write " << shown
                                 << ": it is a FIFO (named pipe) that no process has open for "
                                    "reading; start the reader first");
    SECURE_THROW("cannot write " << shown << ": " << std::strerror(errno));
  }
  FdCloser closer(fd);
  struct stat st {};
  SECURE_CHECK(::fstat(fd, &st) == 0 && (st.st_mode & S_IFMT) == (mode & S_IFMT),
               "cannot write " << shown << ": it changed while being opened (now "
                               << TypeName(st.st_mode) << ")");
  if (fifo) {
    const int flags = ::fcntl(fd, F_GETFL);
    SECURE_CHECK(flags >= 0 && ::fcntl(fd, F_SETFL, flags & ~O_NONBLOCK) == 0,
                 "cannot write " << shown << ": " << std::strerror(errno));
  }
  {
    SigpipeBlocker no_sigpipe;
    WriteAll(fd, bytes, shown);
  }
  SECURE_CHECK(closer.Close() == 0, "cannot write " << shown << ": " << std::strerror(errno));
}

// Removes "<target>.tmp-<pid>-<n>" regular files of processes that no longer exist.
void RemoveStaleTemporaries(const std::string& target) {
  const std::string dir = DirPart(target);
  const std::string prefix = target.substr(dir.size()) + ".tmp-";
  DIR* d = ::opendir(dir.empty() ? "." : dir.c_str());
  if (d == nullptr) return;
  const pid_t self = ::getpid();
  while (const dirent* entry = ::readdir(d)) {
    const std::string_view name = entry->d_name;
    if (name.size() <= prefix.size() || name.substr(0, prefix.size()) != prefix) continue;
    const std::string_view rest = name.substr(prefix.size());
    const std::size_t dash = rest.find('-');
    if (dash == 0 || dash == std::string_view::npos || dash + 1 == rest.size()) continue;
    bool digits = true;
    long long pid = 0;
    for (std::size_t i = 0; i < rest.size() && digits; ++i) {
      if (i == dash) continue;
      digits = rest[i] >= '0' && rest[i] <= '9';
      if (i < dash && digits) {
        pid = pid * 10 + (rest[i] - '0');
        if (pid > INT_MAX) digits = false;
      }
    }
    if (!digits || pid <= 0 || pid == self) continue;
    if (::kill(static_cast<pid_t>(pid), 0) == 0 || errno != ESRCH) continue;  // alive, or EPERM
    const std::string full = dir + std::string(name);
    struct stat st {};
    if (::lstat(full.c_str(), &st) == 0 && S_ISREG(st.st_mode)) ::unlink(full.c_str());
  }
  ::closedir(d);
}

std::string TempPathFor(const std::string& path) {
  static std::atomic<unsigned> counter{0};
  return path + ".tmp-" + std::to_string(::getpid()) + "-" + std::to_string(counter++);
}

// A regular file `target` (described by `existing`, or new if null): temporary file in the same
// directory, fsync, rename over it.
void ReplaceRegular(const std::string& target, const std::string& shown,
                    const struct stat* existing, std::string_view bytes,
                    const std::function<void(const std::string&)>& before_rename) {
  SECURE_CHECK(!target.empty() && target.back() != '/',
               "cannot write " << shown << ": the name ends in '/' (a directory name)");
  InstallTemporaryFileCleanupHandlers();
  RemoveStaleTemporaries(target);
  PendingTemporary tmp(TempPathFor(target));
  // New files get 0666 & ~umask (applied by open). A replacement is created with at most the old
  // file's permission bits (umask may clear some), then gets exactly the old mode below.
  const mode_t create_mode = existing != nullptr ? (existing->st_mode & 0777) : 0666;
  const int flags = O_WRONLY | O_CREAT | O_EXCL | O_NOFOLLOW | O_CLOEXEC;
  int fd = ::open(tmp.path().c_str(), flags, create_mode);
  if (fd < 0 && errno == EEXIST) {
    // Our pid is in the name and the counter is per process: a file of that name was left by an
    // earlier process that had our pid.
    ::unlink(tmp.path().c_str());
    fd = ::open(tmp.path().c_str(), flags, create_mode);
  }
  SECURE_CHECK(fd >= 0, "cannot write " << shown << ": cannot create temporary file '" << tmp.path()
                                        << "': " << std::strerror(errno));
  tmp.MarkCreated();
  FdCloser closer(fd);
  WriteAll(fd, bytes, shown);
  if (existing != nullptr) {
    if (existing->st_uid != ::geteuid() || existing->st_gid != ::getegid()) {
      // Best effort: only root (or the owner, for the group) may do this.
      [[maybe_unused]] const int ignored = ::fchown(fd, existing->st_uid, existing->st_gid);
    }
    SECURE_CHECK(::fchmod(fd, existing->st_mode & 07777) == 0,
                 "cannot write " << shown << ": cannot set the mode of '" << tmp.path()
                                 << "': " << std::strerror(errno));
  }
  SECURE_CHECK(::fsync(fd) == 0, "cannot write " << shown << ": " << std::strerror(errno));
  SECURE_CHECK(closer.Close() == 0, "cannot write " << shown << ": " << std::strerror(errno));
  if (before_rename) before_rename(tmp.path());
  SECURE_CHECK(::rename(tmp.path().c_str(), target.c_str()) == 0,
               "cannot write " << shown << ": rename from '" << tmp.path()
                               << "' failed: " << std::strerror(errno));
  tmp.Commit();
}

void WriteFileImpl(const std::string& path, std::string_view bytes,
                   const std::function<void(const std::string&)>& before_rename) {
  SECURE_CHECK(!path.empty(), "cannot write '': empty file name");
  struct stat st {};
  if (::lstat(path.c_str(), &st) != 0) {
    SECURE_CHECK(errno == ENOENT, "cannot write '" << path << "': " << std::strerror(errno));
    ReplaceRegular(path, Shown(path, path), nullptr, bytes, before_rename);
    return;
  }
  if (S_ISLNK(st.st_mode)) {
    // What the link finally points to, as the kernel sees it (this also follows /proc's magic
    // links, e.g. /dev/stdout -> /proc/self/fd/1 -> pipe:[...], which readlink cannot).
    if (::stat(path.c_str(), &st) != 0) {
      SECURE_CHECK(errno == ENOENT, "cannot write '" << path << "': " << std::strerror(errno));
      const std::string target = ResolveLinks(path);  // dangling: create the target
      ReplaceRegular(target, Shown(path, target), nullptr, bytes, before_rename);
      return;
    }
    if (S_ISREG(st.st_mode)) {
      const std::string target = ResolveLinks(path);
      struct stat target_st {};
      SECURE_CHECK(::lstat(target.c_str(), &target_st) == 0 && S_ISREG(target_st.st_mode),
                   "cannot write " << Shown(path, target) << ": the link changed while being "
                                   << "resolved");
      ReplaceRegular(target, Shown(path, target), &target_st, bytes, before_rename);
      return;
    }
    // A device, FIFO, directory...: the link is opened as given (the kernel follows it).
  }
  const std::string shown = Shown(path, path);
  if (S_ISREG(st.st_mode)) {
    ReplaceRegular(path, shown, &st, bytes, before_rename);
  } else if (S_ISCHR(st.st_mode) || S_ISFIFO(st.st_mode)) {
    WriteDirect(path, shown, st.st_mode, bytes);
  } else {
    SECURE_THROW("cannot write " << shown << ": it is " << TypeName(st.st_mode)
                                 << ", not a regular file; nothing was written");
  }
}

}  // namespace

void RemovePendingTemporaryFiles() noexcept {
  for (Slot& slot : g_slots) {
    int expected = kActive;
    if (!slot.state.compare_exchange_strong(expected, kCleaning, std::memory_order_acq_rel))
      continue;
    ::unlink(slot.path);
    slot.state.store(kActive, std::memory_order_release);
  }
}

void InstallTemporaryFileCleanupHandlers() {
  static std::once_flag once;
  std::call_once(once, [] {
    for (const int sig : {SIGINT, SIGTERM}) {
      struct sigaction current {};
      if (::sigaction(sig, nullptr, &current) != 0) continue;
      // Leave a host program's handler (and an ignored signal) alone.
      if ((current.sa_flags & SA_SIGINFO) != 0 || current.sa_handler != SIG_DFL) continue;
      struct sigaction action {};
      action.sa_handler = CleanupTemporariesOnSignal;
      sigemptyset(&action.sa_mask);
      sigaddset(&action.sa_mask, SIGINT);
      sigaddset(&action.sa_mask, SIGTERM);
      action.sa_flags = SA_RESTART;
      ::sigaction(sig, &action, nullptr);
    }
  });
}

void WriteFileAtomically(const std::string& path, std::string_view bytes) {
  WriteFileImpl(path, bytes, nullptr);
}

namespace internal {
void WriteFileAtomicallyForTest(const std::string& path, std::string_view bytes,
                                const std::function<void(const std::string&)>& before_rename) {
  WriteFileImpl(path, bytes, before_rename);
}
}  // namespace internal

ScratchFile::ScratchFile(const std::string& path) {
  SECURE_CHECK(!path.empty() && path.back() != '/',
               "cannot write '" << path << "': not a file name");
  InstallTemporaryFileCleanupHandlers();
  RemoveStaleTemporaries(path);
  path_ = TempPathFor(path);
  slot_ = RegisterTemporary(path_);
  const int flags = O_WRONLY | O_CREAT | O_EXCL | O_NOFOLLOW | O_CLOEXEC;
  int fd = ::open(path_.c_str(), flags, 0666);
  if (fd < 0 && errno == EEXIST) {  // left by an earlier process that had our pid
    ::unlink(path_.c_str());
    fd = ::open(path_.c_str(), flags, 0666);
  }
  if (fd < 0) {
    const int error = errno;
    UnregisterTemporary(slot_);
    SECURE_THROW("cannot write '" << path << "': cannot create temporary file '" << path_
                                  << "': " << std::strerror(error));
  }
  ::close(fd);
}

ScratchFile::~ScratchFile() {
  ::unlink(path_.c_str());
  UnregisterTemporary(slot_);
}

std::string ReadFile(const std::string& path) {
  // Only a regular file of bounded size (input_limits.h): a FIFO without a writer would block
  // here, a directory read as empty, and /dev/zero (or a file that grows) never end.
  CheckRegularInputFile(path);
  const std::uint64_t limit = GetInputLimits().max_input_bytes;
  std::ifstream in(path, std::ios::binary);
  SECURE_CHECK(in.good(), "cannot open '" << path << "': " << std::strerror(errno));
  std::string out;
  char buffer[1 << 16];
  while (in.read(buffer, sizeof buffer) || in.gcount() > 0) {
    out.append(buffer, static_cast<std::size_t>(in.gcount()));
    SECURE_CHECK(out.size() <= limit, "cannot read '" << path << "': more than the input limit of "
                                                      << limit
                                                      << " bytes (it grew while being read; "
                                                         "raise the limit with "
                                                         "SECURE_MAX_INPUT_BYTES)");
  }
  SECURE_CHECK(!in.bad(), "cannot read '" << path << "'");
  return out;
}

}  // namespace secure
