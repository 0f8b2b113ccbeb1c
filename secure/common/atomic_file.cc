#include "secure/common/atomic_file.h"

#include <fcntl.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <sstream>

#include "secure/common/error.h"

namespace secure {
namespace {

std::string TempPathFor(const std::string& path) {
  static std::atomic<unsigned> counter{0};
  return path + ".tmp-" + std::to_string(::getpid()) + "-" + std::to_string(counter++);
}

}  // namespace

void WriteFileAtomically(const std::string& path, std::string_view bytes) {
  const std::string tmp = TempPathFor(path);
  const int fd = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  SECURE_CHECK(fd >= 0, "cannot write '" << path << "': cannot create temporary file '" << tmp
                                         << "': " << std::strerror(errno));
  const char* data = bytes.data();
  std::size_t left = bytes.size();
  while (left > 0) {
    const ssize_t n = ::write(fd, data, left);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) {
      const int err = errno;
      ::close(fd);
      ::unlink(tmp.c_str());
      SECURE_THROW("cannot write '" << path << "': " << std::strerror(err));
    }
    data += n;
    left -= static_cast<std::size_t>(n);
  }
  if (::fsync(fd) != 0 || ::close(fd) != 0) {
    const int err = errno;
    ::unlink(tmp.c_str());
    SECURE_THROW("cannot write '" << path << "': " << std::strerror(err));
  }
  if (std::rename(tmp.c_str(), path.c_str()) != 0) {
    const int err = errno;
    ::unlink(tmp.c_str());
    SECURE_THROW("cannot write '" << path << "': rename from '" << tmp
                                  << "' failed: " << std::strerror(err));
  }
}

std::string ReadFile(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  SECURE_CHECK(in.good(), "cannot open '" << path << "': " << std::strerror(errno));
  std::ostringstream buffer;
  buffer << in.rdbuf();
  SECURE_CHECK(!in.bad(), "cannot read '" << path << "'");
  return buffer.str();
}

}  // namespace secure
