#pragma once
// File-system helpers whose failures are user-facing secure::Error messages that name the path
// and the reason (never a std::filesystem::filesystem_error escaping to main).

#include <string>

namespace secure {

/// Creates `path` and its missing parents (as std::filesystem::create_directories); an existing
/// directory is fine. Does nothing for an empty path.
/// @throws secure::Error naming the path and the reason, e.g.
///   "cannot create directory 'out': File exists (not a directory)",
///   "cannot create directory 'a/f/b': 'a/f' is not a directory",
///   "cannot create directory '/proc/x': Permission denied".
void CreateDirectories(const std::string& path);

/// Checks that `path` can be read as a file: it must not be a directory ("'d' is a directory,
/// not a file"). A missing path passes (opening it then reports the error); pipes and devices
/// pass (a FIFO can hold a config or CSV file).
/// @throws secure::Error naming the path.
void CheckNotADirectory(const std::string& path);

}  // namespace secure
