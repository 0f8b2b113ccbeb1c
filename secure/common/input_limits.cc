#include "secure/common/input_limits.h"

#include <pthread.h>
#include <sys/stat.h>

#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <iostream>
#include <limits>
#include <mutex>

#include "secure/common/error.h"

namespace secure {
namespace {

template <typename T>
void FromEnvironment(const char* name, T* value) {
  const char* text = std::getenv(name);
  if (text == nullptr || *text == '\0') return;
  char* end = nullptr;
  errno = 0;
  const unsigned long long v = std::strtoull(text, &end, 10);
  if (errno != 0 || end == text || *end != '\0' || v == 0 || text[0] == '-' ||
      v > static_cast<unsigned long long>(std::numeric_limits<T>::max())) {
    std::cerr << "secure: note: ignoring " << name << "='" << text
              << "' (expected a positive integer)\n";
    return;
  }
  *value = static_cast<T>(v);
}

std::mutex& LimitsMutex() {
  // Held across fork() (the HDF5 readers' child process reads the limits): a child never
  // inherits it locked by a thread it does not have.
  static std::mutex* m = [] {
    auto* mutex = new std::mutex;
    ::pthread_atfork([] { LimitsMutex().lock(); }, [] { LimitsMutex().unlock(); },
                     [] { LimitsMutex().unlock(); });
    return mutex;
  }();
  return *m;
}

InputLimits& Limits() {
  static InputLimits limits = [] {
    InputLimits l;
    FromEnvironment("SECURE_MAX_INPUT_BYTES", &l.max_input_bytes);
    FromEnvironment("SECURE_MAX_CONFIG_NODES", &l.max_config_nodes);
    FromEnvironment("SECURE_MAX_CONFIG_DEPTH", &l.max_config_depth);
    FromEnvironment("SECURE_MAX_HDF5_MEMORY", &l.max_hdf5_memory_bytes);
    FromEnvironment("SECURE_MAX_HDF5_SECONDS", &l.max_hdf5_seconds);
    return l;
  }();
  return limits;
}

}  // namespace

const InputLimits& GetInputLimits() {
  std::lock_guard<std::mutex> lock(LimitsMutex());
  return Limits();
}

void SetInputLimits(const InputLimits& limits) {
  std::lock_guard<std::mutex> lock(LimitsMutex());
  Limits() = limits;
}

std::uint64_t Hdf5ReaderMemoryLimit(std::uint64_t file_bytes) {
  const std::uint64_t set = GetInputLimits().max_hdf5_memory_bytes;
  if (set != 0) return set;
  const std::uint64_t gib = std::uint64_t{1} << 30;
  const std::uint64_t max = std::numeric_limits<std::uint64_t>::max();
  return file_bytes > (max - gib) / 8 ? max : gib + 8 * file_bytes;
}

std::string FileTypeName(unsigned mode) {
  switch (mode & S_IFMT) {
    case S_IFREG: return "a regular file";
    case S_IFDIR: return "a directory";
    case S_IFIFO: return "a FIFO";
    case S_IFCHR: return "a character device";
    case S_IFBLK: return "a block device";
    case S_IFSOCK: return "a socket";
    case S_IFLNK: return "a symbolic link";
    default: return "not a regular file";
  }
}

std::uint64_t CheckRegularInputFile(const std::string& path) {
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0) {
    const int error = errno;
    struct stat link {};
    if (error == ENOENT && ::lstat(path.c_str(), &link) == 0 && S_ISLNK(link.st_mode))
      SECURE_THROW("cannot read '" << path << "': a dangling symbolic link (its target does not "
                                               "exist)");
    SECURE_THROW("cannot open '" << path << "': " << std::strerror(error));
  }
  SECURE_CHECK(S_ISREG(st.st_mode), "cannot read '" << path << "': it is "
                                                    << FileTypeName(st.st_mode)
                                                    << ", not a regular file");
  const std::uint64_t size = static_cast<std::uint64_t>(st.st_size);
  const std::uint64_t limit = GetInputLimits().max_input_bytes;
  SECURE_CHECK(size <= limit, "cannot read '" << path << "': " << size
                                              << " bytes, more than the input limit of " << limit
                                              << " bytes (raise it with SECURE_MAX_INPUT_BYTES or "
                                                 "--max-input-bytes)");
  return size;
}

}  // namespace secure
