// The HDF5 readers' guard (issue 34): every HDF5 file is read in a child process, because
// libhdf5 1.10.8 itself crashes (a SEGV in H5F__accum_read) or allocates gigabytes on some
// malformed files (tests/fuzz/findings/hdf5_fuzz/). The child (fork) limits its address space
// (RLIMIT_AS: what it has plus Hdf5ReaderMemoryLimit), turns off core dumps, runs the in-process
// reader (hdf5_read.cc) and sends the decoded arrays, or the reader's one-line error, through a
// pipe. The parent turns the child's death by a signal, an allocation over its limit, or a read
// longer than its time limit (GetInputLimits().max_hdf5_seconds), into one secure::Error naming
// the file. Writing (hdf5_write.cc) stays in this process; both sides hold
// Hdf5LibraryMutex() while they use libhdf5 or fork, so a child never inherits it mid-call.

#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <sys/prctl.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <functional>
#include <mutex>
#include <new>
#include <string>
#include <vector>

#include "secure/common/error.h"
#include "secure/common/input_limits.h"
#include "secure/data/data.h"
#include "secure/data/internal/hdf5_mutex.h"

namespace secure::data {
namespace {

// The child's reply: one tag byte, then the payload ('O') or a message ('E'); 'M': an
// allocation failed (std::bad_alloc) under the memory limit.
constexpr char kOk = 'O', kError = 'E', kNoMemory = 'M';

// Appends values to a byte string (the child) and takes them off it (the parent), in this
// machine's layout: both ends are the same program.
class Encoder {
 public:
  void U64(std::uint64_t v) { bytes_.append(reinterpret_cast<const char*>(&v), sizeof v); }
  void Str(const std::string& s) {
    U64(s.size());
    bytes_ += s;
  }
  void Strings(const std::vector<std::string>& v) {
    U64(v.size());
    for (const std::string& s : v) Str(s);
  }
  void Longs(const std::vector<long>& v) {
    U64(v.size());
    for (long x : v) U64(static_cast<std::uint64_t>(x));
  }
  void Matrix(const Eigen::MatrixXf& m) {
    U64(static_cast<std::uint64_t>(m.rows()));
    U64(static_cast<std::uint64_t>(m.cols()));
    bytes_.append(reinterpret_cast<const char*>(m.data()), sizeof(float) * m.size());
  }
  std::string& bytes() { return bytes_; }

 private:
  std::string bytes_;
};

class Decoder {
 public:
  Decoder(const std::string& bytes, std::size_t at, const std::string& path)
      : bytes_(bytes), at_(at), path_(path) {}
  std::uint64_t U64() {
    std::uint64_t v = 0;
    std::memcpy(&v, Take(sizeof v), sizeof v);
    return v;
  }
  std::string Str() {
    const std::uint64_t n = U64();
    return std::string(Take(n), n);
  }
  std::vector<std::string> Strings() {
    std::vector<std::string> v(Count(sizeof(std::uint64_t)));
    for (std::string& s : v) s = Str();
    return v;
  }
  std::vector<long> Longs() {
    std::vector<long> v(Count(sizeof(std::uint64_t)));
    for (long& x : v) x = static_cast<long>(U64());
    return v;
  }
  Eigen::MatrixXf Matrix() {
    const std::uint64_t rows = U64(), cols = U64();
    SECURE_CHECK(cols == 0 || rows <= Left() / sizeof(float) / cols, Broken());
    Eigen::MatrixXf m(static_cast<Eigen::Index>(rows), static_cast<Eigen::Index>(cols));
    std::memcpy(m.data(), Take(sizeof(float) * rows * cols), sizeof(float) * rows * cols);
    return m;
  }
  void End() const { SECURE_CHECK(at_ == bytes_.size(), Broken()); }

 private:
  std::size_t Left() const { return bytes_.size() - at_; }
  // A count of items of at least `item` bytes each, checked against what is left.
  std::size_t Count(std::size_t item) {
    const std::uint64_t n = U64();
    SECURE_CHECK(n <= Left() / item, Broken());
    return static_cast<std::size_t>(n);
  }
  const char* Take(std::uint64_t n) {
    SECURE_CHECK(n <= Left(), Broken());
    const char* p = bytes_.data() + at_;
    at_ += static_cast<std::size_t>(n);
    return p;
  }
  std::string Broken() const {
    return path_ + ": internal error: the HDF5 reader process sent a malformed reply";
  }
  const std::string& bytes_;
  std::size_t at_;
  const std::string& path_;
};

bool WriteAll(int fd, const char* data, std::size_t size) {
  while (size > 0) {
    const ssize_t n = ::write(fd, data, size);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) return false;
    data += n;
    size -= static_cast<std::size_t>(n);
  }
  return true;
}

// The child's address space now (/proc/self/statm's first field), in bytes; 0 if unknown.
std::uint64_t AddressSpaceBytes() {
  std::FILE* f = std::fopen("/proc/self/statm", "r");
  if (f == nullptr) return 0;
  unsigned long long pages = 0;
  const int got = std::fscanf(f, "%llu", &pages);
  std::fclose(f);
  return got == 1 ? pages * static_cast<std::uint64_t>(::sysconf(_SC_PAGESIZE)) : 0;
}

// The child: limits, the read, the reply; never returns.
[[noreturn]] void RunChild(int fd, std::uint64_t memory_limit,
                           const std::function<void(Encoder&)>& read) {
  // Die of a crash plainly (no sanitizer or fuzzer handler inherited from the parent, no core
  // file): the parent reports it.
  for (int sig : {SIGSEGV, SIGBUS, SIGFPE, SIGILL, SIGABRT}) ::signal(sig, SIG_DFL);
  // The child speaks only through the pipe: what libhdf5 or a sanitizer's allocator prints as
  // it dies (an ASan build reports its own out-of-memory before aborting) must not add lines
  // to the parent's one-line error.
  const int null_fd = ::open("/dev/null", O_WRONLY | O_CLOEXEC);
  if (null_fd >= 0) {
    ::dup2(null_fd, STDOUT_FILENO);
    ::dup2(null_fd, STDERR_FILENO);
  }
  // No core dump at all: RLIMIT_CORE = 0 stops a core file, but where core_pattern pipes to a
  // helper (systemd-coredump, apport) the kernel ignores it, and the dump of a process with
  // libtorch mapped holds the child's death, and so the reply, for as long as the helper takes.
  // A process that is not dumpable is never dumped.
  struct rlimit no_core {0, 0};
  ::setrlimit(RLIMIT_CORE, &no_core);
  ::prctl(PR_SET_DUMPABLE, 0, 0, 0, 0);
  // Few descriptors: a process the child starts (a sanitizer's symbolizer) closes every
  // descriptor up to this limit first, which takes minutes where the limit is 2^30.
  struct rlimit files {};
  if (::getrlimit(RLIMIT_NOFILE, &files) == 0 && files.rlim_cur > 1024) {
    files.rlim_cur = 1024;
    ::setrlimit(RLIMIT_NOFILE, &files);
  }
  // The limit on top of what the parent had mapped (a sanitizer build maps terabytes of shadow).
  const std::uint64_t base = AddressSpaceBytes();
  struct rlimit as {};
  as.rlim_cur = as.rlim_max =
      memory_limit > RLIM_INFINITY - base ? RLIM_INFINITY : static_cast<rlim_t>(base + memory_limit);
  ::setrlimit(RLIMIT_AS, &as);
  Encoder reply;
  char tag = kOk;
  try {
    reply.bytes().push_back(kOk);
    read(reply);
  } catch (const std::bad_alloc&) {
    tag = kNoMemory;
  } catch (const std::exception& e) {
    tag = kError;
    try {
      reply.bytes().assign(1, kError);
      reply.bytes() += e.what();
    } catch (const std::bad_alloc&) {
      tag = kNoMemory;
    }
  }
  if (tag == kNoMemory) {
    const char m = kNoMemory;
    ::_exit(WriteAll(fd, &m, 1) ? 0 : 2);
  }
  ::_exit(WriteAll(fd, reply.bytes().data(), reply.bytes().size()) ? 0 : 2);
}

std::string MemoryNote(std::uint64_t limit) {
  return "the HDF5 reader's memory limit of " + std::to_string(limit) +
         " bytes (1 GiB + 8 x the file's size unless set; raise it with SECURE_MAX_HDF5_MEMORY "
         "or --max-hdf5-memory)";
}

// What ReadReplyAndWait saw: waitpid's result and status, and whether the deadline passed first.
struct ChildEnd {
  pid_t waited = -1;
  int status = 0;
  bool timed_out = false;
};

// Reads the child's reply from `fd` until end of file and the child's exit, or until the child
// has exited and the pipe holds nothing more, or until `deadline`, whichever comes first; then
// kills what is left of the child's process group and reaps the child. (A process the child
// started, such as a sanitizer's symbolizer, may hold the pipe open after the child died, and end
// of file alone would wait for it; a child stuck in a loop of libhdf5's, or in a lock another
// thread held at fork, would never exit.)
ChildEnd ReadReplyAndWait(int fd, pid_t pid, std::chrono::steady_clock::time_point deadline,
                          std::string* reply) {
  // Whether the child has exited, left a zombie (WNOWAIT) so its process group stays its own.
  // (waitid fails only if SIGCHLD is ignored: then there is nothing to wait for, and the reply
  // alone decides.)
  const auto exited = [pid] {
    siginfo_t info{};
    int r = -1;
    do {
      r = ::waitid(P_PID, static_cast<id_t>(pid), &info, WEXITED | WNOWAIT | WNOHANG);
    } while (r < 0 && errno == EINTR);
    return r < 0 || info.si_pid == pid;
  };
  char buffer[1 << 16];
  bool pipe_open = true, child_exited = false;
  ChildEnd end;
  while (pipe_open || !child_exited) {
    const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(
        deadline - std::chrono::steady_clock::now());
    if (!child_exited && left.count() <= 0) {
      end.timed_out = true;
      break;
    }
    // After the child's exit, only what is already in the pipe is read.
    const int tick = child_exited ? 0
                                  : static_cast<int>(std::clamp<long long>(left.count(), 1, 100));
    if (pipe_open) {
      struct pollfd p {fd, POLLIN, 0};
      const int ready = ::poll(&p, 1, tick);
      if (ready < 0 && errno == EINTR) continue;
      if (ready > 0) {
        const ssize_t n = ::read(fd, buffer, sizeof buffer);
        if (n < 0 && errno == EINTR) continue;
        if (n > 0) {
          reply->append(buffer, static_cast<std::size_t>(n));
          continue;
        }
      }
      if (ready != 0 || child_exited) pipe_open = false;  // end of file, an error, or drained
    } else {
      ::usleep(static_cast<useconds_t>(tick) * 1000);
    }
    if (!child_exited) child_exited = exited();
  }
  ::kill(-pid, SIGKILL);
  // Reaps the child, but waits for it at most kReapSeconds after SIGKILL: a process the kernel
  // is still tearing down (a dump that a signal does not interrupt on some kernels) must not
  // hold up the caller. One that is not reaped stays a zombie until this process ends.
  constexpr int kReapSeconds = 10;
  const auto reap_deadline = std::chrono::steady_clock::now() + std::chrono::seconds(kReapSeconds);
  for (;;) {
    end.waited = ::waitpid(pid, &end.status, WNOHANG);
    if (end.waited < 0 && errno == EINTR) continue;
    if (end.waited != 0 || std::chrono::steady_clock::now() >= reap_deadline) break;
    ::usleep(2000);
  }
  return end;
}

// Reads `path` with `read` in a child process; returns the child's reply (the tag, then the
// payload). Throws the child's error, or one naming its death.
std::string RunGuarded(const std::string& path, const std::function<void(Encoder&)>& read) {
  // Missing files, FIFOs, devices and oversized files are refused here, without a child.
  const std::uint64_t file_bytes = CheckRegularInputFile(path);
  const std::uint64_t limit = Hdf5ReaderMemoryLimit(file_bytes);
  // The time limit counts from here (capped at ten years, so that the clock cannot overflow).
  const std::uint64_t seconds = std::min<std::uint64_t>(GetInputLimits().max_hdf5_seconds,
                                                        std::uint64_t{10} * 365 * 24 * 3600);
  const auto deadline =
      std::chrono::steady_clock::now() + std::chrono::seconds(static_cast<long long>(seconds));
  int fds[2];
  SECURE_CHECK(::pipe2(fds, O_CLOEXEC) == 0,
               path << ": cannot start the HDF5 reader process (pipe: " << std::strerror(errno)
                    << ")");
  pid_t pid = -1;
  {
    std::lock_guard<std::mutex> lock(hdf5::Hdf5LibraryMutex());
    pid = ::fork();
    if (pid == 0) {
      ::setpgid(0, 0);  // its own process group, which the parent kills after the reply
      ::close(fds[0]);
      RunChild(fds[1], limit, read);
    }
  }
  const int fork_error = errno;
  if (pid > 0) ::setpgid(pid, pid);  // (as the child does: whichever runs first)
  ::close(fds[1]);
  if (pid < 0) {
    ::close(fds[0]);
    SECURE_THROW(path << ": cannot start the HDF5 reader process (fork: "
                      << std::strerror(fork_error) << ")");
  }
  std::string reply;
  const ChildEnd end = ReadReplyAndWait(fds[0], pid, deadline, &reply);
  ::close(fds[0]);
  const pid_t waited = end.waited;
  const int status = end.status;
  SECURE_CHECK(!end.timed_out,
               path << ": the HDF5 reader process took longer than " << seconds
                    << " s and was stopped (a corrupt or malicious file, or a large one on a slow "
                       "disk: raise the limit with SECURE_MAX_HDF5_SECONDS or "
                       "--max-hdf5-seconds)");
  // (waitpid fails only if SIGCHLD is ignored; then the reply alone decides.)
  if (waited == pid && WIFSIGNALED(status)) {
    const int sig = WTERMSIG(status);
    const char* name = sigabbrev_np(sig);
    SECURE_THROW(path << ": the HDF5 library crashed reading the file (signal " << sig
                      << (name != nullptr ? std::string(", SIG") + name : std::string())
                      << "): a corrupt or malicious file, or one needing more than "
                      << MemoryNote(limit));
  }
  SECURE_CHECK(!reply.empty(), path << ": the HDF5 reader process exited with status "
                                    << (waited == pid ? WEXITSTATUS(status) : -1)
                                    << " without a reply (a corrupt or malicious file, or one "
                                       "needing more than "
                                    << MemoryNote(limit) << ")");
  SECURE_CHECK(reply[0] != kNoMemory,
               path << ": reading the file needs more memory than " << MemoryNote(limit));
  if (reply[0] == kError) throw Error(reply.substr(1));
  SECURE_CHECK(reply[0] == kOk,
               path << ": internal error: the HDF5 reader process sent a malformed reply");
  return reply;
}

// The readers' results through the pipe: Encode in the child, Decode in the parent.
void Encode(Encoder& e, const Hdf5Contents& c) {
  e.U64(c.has_demonstrations ? 1 : 0);
  for (const auto* v : {&c.observation_features, &c.unreadable_obs_keys, &c.action_features,
                        &c.state_sets})
    e.Strings(*v);
}
void Decode(Decoder& d, const std::string& /*path*/, Hdf5Contents* c) {
  c->has_demonstrations = d.U64() != 0;
  for (auto* v : {&c->observation_features, &c->unreadable_obs_keys, &c->action_features,
                  &c->state_sets})
    *v = d.Strings();
}
void Encode(Encoder& e, const TrajectorySet& t) {
  e.Strings(t.state_features);
  e.Strings(t.action_features);
  e.Matrix(t.states);
  e.Matrix(t.actions);
  e.Longs(t.episode_begin);
}
void Decode(Decoder& d, const std::string& path, TrajectorySet* t) {
  t->source = path;
  t->state_features = d.Strings();
  t->action_features = d.Strings();
  t->states = d.Matrix();
  t->actions = d.Matrix();
  t->episode_begin = d.Longs();
}
void Encode(Encoder& e, const StateSet& s) {
  e.Strings(s.features);
  e.Matrix(s.states);
}
void Decode(Decoder& d, const std::string& path, StateSet* s) {
  s->source = path;
  s->features = d.Strings();
  s->states = d.Matrix();
}

// `read()` (an in-process reader of `path`) run in a child process, its result sent back.
template <typename T, typename Read>
T ReadGuarded(const std::string& path, const Read& read) {
  const std::string reply = RunGuarded(path, [&](Encoder& e) { Encode(e, read()); });
  Decoder d(reply, 1, path);
  T value;
  Decode(d, path, &value);
  d.End();
  return value;
}

}  // namespace

Hdf5Contents InspectHdf5(const std::string& path) {
  return ReadGuarded<Hdf5Contents>(path, [&] { return internal::InspectHdf5InProcess(path); });
}

namespace internal {

std::string RunInHdf5ReaderProcess(const std::string& path,
                                   const std::function<void(std::string*)>& work) {
  return RunGuarded(path, [&](Encoder& e) { work(&e.bytes()); }).substr(1);
}

TrajectorySet ReadHdf5Trajectories(const std::string& path,
                                   const std::vector<std::string>& state_features,
                                   const std::vector<std::string>& action_features) {
  return ReadGuarded<TrajectorySet>(path, [&] {
    return ReadHdf5TrajectoriesInProcess(path, state_features, action_features);
  });
}

StateSet ReadHdf5StateSet(const std::string& path, const std::vector<std::string>& features,
                          const std::string& label) {
  return ReadGuarded<StateSet>(
      path, [&] { return ReadHdf5StateSetInProcess(path, features, label); });
}

}  // namespace internal

}  // namespace secure::data
