#include "secure/common/filesystem.h"

#include <filesystem>
#include <system_error>

#include "secure/common/error.h"

namespace secure {

namespace fs = std::filesystem;

void CreateDirectories(const std::string& path) {
  if (path.empty()) return;
  const fs::path p(path);
  std::error_code ec;
  if (fs::is_directory(p, ec)) return;
  fs::create_directories(p, ec);
  if (!ec && fs::is_directory(p)) return;
  // Say why: an existing non-directory at the path or at one of its parents, or the OS's reason.
  if (fs::is_symlink(fs::symlink_status(p, ec)) && !fs::exists(fs::status(p, ec))) {
    SECURE_THROW("cannot create directory '" << path
                                             << "': it is a dangling symbolic link (to '"
                                             << fs::read_symlink(p, ec).string()
                                             << "', which does not exist)");
  }
  if (fs::exists(fs::symlink_status(p, ec)) && !fs::is_directory(p, ec)) {
    SECURE_THROW("cannot create directory '" << path << "': File exists (not a directory)");
  }
  for (fs::path prefix = p.parent_path(); !prefix.empty() && prefix != prefix.root_path();
       prefix = prefix.parent_path()) {
    std::error_code status_ec;
    const fs::file_status status = fs::status(prefix, status_ec);
    if (fs::exists(status) && !fs::is_directory(status)) {
      SECURE_THROW("cannot create directory '" << path << "': '" << prefix.string()
                                               << "' is not a directory");
    }
  }
  SECURE_THROW("cannot create directory '"
               << path << "': " << (ec ? ec.message() : std::string("unknown error")));
}

void CheckNotADirectory(const std::string& path) {
  std::error_code ec;
  SECURE_CHECK(!fs::is_directory(fs::path(path), ec),
               "cannot read '" << path << "': is a directory, not a file");
}

}  // namespace secure
