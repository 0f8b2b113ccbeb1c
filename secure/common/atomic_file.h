#pragma once
// Writing output files safely. What WriteFileAtomically(path, bytes) does depends on what `path`
// is (lstat, before anything is written):
//
//   does not exist      a new regular file, created atomically (see below) with mode
//                       0666 & ~umask, like ordinary tools.
//   regular file        replaced atomically: the content goes to "<path>.tmp-<pid>-<n>" in the
//                       same directory, is flushed and fsync'ed, then renamed over <path>. A
//                       reader never sees a half-written file and a failed write leaves the
//                       previous file untouched. The replaced file's mode bits (and, where
//                       permitted, its owner and group) are kept. Other hard links to the old
//                       file keep the old content (rename replaces the name, not the inode).
//   symbolic link       written through: the link (a chain of links, relative ones resolved
//                       against the link's directory) is resolved and its final target is
//                       written as above, in the target's directory; the link itself stays.
//                       A dangling link creates its target (the target's directory must exist).
//   character device    written directly (open O_WRONLY, no temporary, no rename): /dev/null,
//                       /dev/stdout, a terminal. The device node is never replaced.
//   FIFO (named pipe)   written directly. It is opened with O_NONBLOCK first, so a FIFO that no
//                       process has open for reading is an error ("no reader") instead of a
//                       hang; O_NONBLOCK is then cleared and the writes block until the reader
//                       has taken the data. A reader that closes early is an error (no SIGPIPE).
//   anything else       (a directory, a socket, a block device) an error naming the path and
//                       its type; nothing is touched.
//
// Every failure throws secure::Error with a one-line message naming the path.
//
// Temporary files. While "<path>.tmp-<pid>-<n>" is being written its name is in a fixed-size,
// async-signal-safe registry. The first atomic write installs handlers for SIGINT and SIGTERM
// that unlink the registered temporaries, restore the default disposition and re-raise the
// signal, so the process still dies "killed by SIGINT/SIGTERM". A handler is only installed where
// the current disposition is SIG_DFL: a host program that installed its own handler (or ignores
// the signal) keeps it, and should call RemovePendingTemporaryFiles() from its handler. SIGKILL
// cannot be caught: each write of <path> first removes the stale temporaries "<path>.tmp-<pid>-<n>"
// in that directory whose <pid> is not a live process (kill(pid, 0) fails with ESRCH; only
// regular files; processes of another PID namespace sharing the directory look dead).

#include <functional>
#include <string>
#include <string_view>

namespace secure {

/// Writes `bytes` to `path` as described above. Throws secure::Error naming the path on failure.
void WriteFileAtomically(const std::string& path, std::string_view bytes);

/// A scratch file next to `path` for content that is written by other means (e.g. by a child
/// process such as an encoder) before WriteFileAtomically installs it at `path`: named
/// "<path>.tmp-<pid>-<n>" like the temporaries above (so a later write of `path` sweeps it if
/// this process was killed), created empty and exclusively, registered for the SIGINT/SIGTERM
/// cleanup, and removed by the destructor.
class ScratchFile {
 public:
  /// @throws secure::Error naming `path` if the file cannot be created (e.g. its directory does
  /// not exist or is not writable).
  explicit ScratchFile(const std::string& path);
  ~ScratchFile();
  ScratchFile(const ScratchFile&) = delete;
  ScratchFile& operator=(const ScratchFile&) = delete;
  const std::string& path() const { return path_; }

 private:
  std::string path_;
  int slot_ = -1;
};

/// Reads a whole file. Throws secure::Error naming the path if it cannot be opened or read.
std::string ReadFile(const std::string& path);

/// Installs the SIGINT/SIGTERM cleanup handlers (for signals whose disposition is SIG_DFL). Called
/// by the first WriteFileAtomically; a program may call it earlier. Idempotent, thread-safe.
void InstallTemporaryFileCleanupHandlers();

/// Unlinks every temporary file currently being written by WriteFileAtomically in this process.
/// Async-signal-safe: for the signal handlers of programs that install their own.
void RemovePendingTemporaryFiles() noexcept;

namespace internal {
/// WriteFileAtomically with `before_rename(temporary)` called after the temporary file is
/// written, fsync'ed and closed, just before the rename (not called for devices and FIFOs).
/// For tests: lets them interrupt a write at a known point.
void WriteFileAtomicallyForTest(const std::string& path, std::string_view bytes,
                                const std::function<void(const std::string&)>& before_rename);
}  // namespace internal

}  // namespace secure
