#pragma once
// Helpers shared by the libFuzzer targets in this folder.
#include <unistd.h>

#include <cstddef>
#include <cstdint>
#include <fstream>
#include <string>

namespace secure::fuzz {

/// A per-process scratch file for readers that take a path; rewritten for every input and
/// removed when the fuzzer exits.
struct ScratchFile {
  std::string path;
  ~ScratchFile() { ::unlink(path.c_str()); }
};

inline const std::string& ScratchPath(const char* suffix) {
  static const ScratchFile file{[suffix] {
    const char* dir = ::access("/dev/shm", W_OK) == 0 ? "/dev/shm" : "/tmp";
    return std::string(dir) + "/secure_fuzz_" + std::to_string(::getpid()) + suffix;
  }()};
  return file.path;
}

inline const std::string& WriteScratch(const std::string& bytes, const char* suffix) {
  const std::string& path = ScratchPath(suffix);
  std::ofstream(path, std::ios::binary | std::ios::trunc).write(bytes.data(),
                                                                 static_cast<long>(bytes.size()));
  return path;
}

}  // namespace secure::fuzz
