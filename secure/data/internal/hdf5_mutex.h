#pragma once
// The one mutex around libhdf5 in this process (INTERNAL to secure/data/hdf5_*.cc): the writer
// holds it while it calls libhdf5, the reader's guard (hdf5_guard.cc) while it forks, so the
// child process that reads a file never inherits libhdf5 in the middle of another thread's call.
#include <mutex>

namespace secure::data::hdf5 {

inline std::mutex& Hdf5LibraryMutex() {
  static std::mutex m;
  return m;
}

}  // namespace secure::data::hdf5
