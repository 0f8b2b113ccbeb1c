#pragma once
// Atomic file writes: the content goes to "<path>.tmp-<pid>-<n>" in the same directory, is
// flushed and fsync'ed, then renamed over <path>. A reader never sees a half-written file and a
// failed write leaves any previous file at <path> untouched.

#include <string>
#include <string_view>

namespace secure {

/// Writes `bytes` to `path` atomically. Throws secure::Error naming the path on any failure.
void WriteFileAtomically(const std::string& path, std::string_view bytes);

/// Reads a whole file. Throws secure::Error naming the path if it cannot be opened or read.
std::string ReadFile(const std::string& path);

}  // namespace secure
