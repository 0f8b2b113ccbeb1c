#include "secure/common/atomic_file.h"
#include "tests/test_util.h"

#include <fcntl.h>
#include <gtest/gtest.h>
#include <poll.h>
#include <signal.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/sysmacros.h>
#include <sys/un.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>
#include <thread>
#include <vector>

#include "secure/common/error.h"

namespace secure {
namespace {

namespace fs = std::filesystem;

using secure::test::ErrorOf;

// A fresh empty directory per test, removed afterwards.
class AtomicFileTest : public ::testing::Test {
 protected:
  void SetUp() override {
    static std::atomic<int> counter{0};
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    dir_ = fs::path(::testing::TempDir()) / ("secure_atomic_file_" + std::to_string(::getpid()) +
                                             "_" + info->name() + "_" + std::to_string(counter++));
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override {
    std::error_code ec;
    fs::remove_all(dir_, ec);
  }

  std::vector<std::string> Entries() const {
    std::vector<std::string> names;
    for (const auto& entry : fs::directory_iterator(dir_))
      names.push_back(entry.path().filename().string());
    return names;
  }

  fs::path dir_;
};

TEST_F(AtomicFileTest, WriteThenReadReturnsTheBytes) {
  const std::string path = (dir_ / "a.txt").string();
  WriteFileAtomically(path, "hello\nworld");
  EXPECT_EQ(ReadFile(path), "hello\nworld");
}

TEST_F(AtomicFileTest, RoundTripsBinaryContentWithNulBytes) {
  std::string bytes;
  for (int i = 0; i < 256; ++i) bytes.push_back(static_cast<char>(i));
  bytes += std::string(3, '\0') + "\r\n\x1a";
  const std::string path = (dir_ / "bin").string();
  WriteFileAtomically(path, bytes);
  EXPECT_EQ(ReadFile(path), bytes);
  EXPECT_EQ(fs::file_size(path), bytes.size());
}

TEST_F(AtomicFileTest, RoundTripsAnEmptyFile) {
  const std::string path = (dir_ / "empty").string();
  WriteFileAtomically(path, "");
  EXPECT_TRUE(fs::exists(path));
  EXPECT_EQ(ReadFile(path), "");
}

TEST_F(AtomicFileTest, RoundTripsALargeFile) {
  std::string bytes(5 * 1000 * 1000 + 17, '\0');
  for (std::size_t i = 0; i < bytes.size(); ++i) bytes[i] = static_cast<char>((i * 131) % 251);
  const std::string path = (dir_ / "large").string();
  WriteFileAtomically(path, bytes);
  EXPECT_TRUE(ReadFile(path) == bytes);
}

TEST_F(AtomicFileTest, OverwriteReplacesTheWholeContent) {
  const std::string path = (dir_ / "a.txt").string();
  WriteFileAtomically(path, "a long first version of the file");
  WriteFileAtomically(path, "short");
  EXPECT_EQ(ReadFile(path), "short");  // no tail of the longer first version
}

TEST_F(AtomicFileTest, WriteLeavesNoTemporaryFilesBehind) {
  const std::string path = (dir_ / "model.json").string();
  WriteFileAtomically(path, "1");
  WriteFileAtomically(path, "2");
  WriteFileAtomically((dir_ / "other").string(), "3");
  auto names = Entries();
  std::sort(names.begin(), names.end());
  EXPECT_EQ(names, (std::vector<std::string>{"model.json", "other"}));
}

TEST_F(AtomicFileTest, WriteIntoAMissingDirectoryThrowsNamingThePath) {
  const std::string path = (dir_ / "no_such_dir" / "file.txt").string();
  const std::string message = ErrorOf([&] { WriteFileAtomically(path, "x"); });
  EXPECT_HAS(message, path);
  EXPECT_FALSE(fs::exists(dir_ / "no_such_dir"));
  EXPECT_TRUE(Entries().empty());
}

TEST_F(AtomicFileTest, AScratchFileLivesNextToThePathUntilDestroyed) {
  const std::string path = (dir_ / "video.mp4").string();
  std::string scratch_path;
  {
    ScratchFile scratch(path);
    scratch_path = scratch.path();
    EXPECT_EQ(scratch_path.rfind(path + ".tmp-" + std::to_string(::getpid()) + "-", 0), 0u)
        << scratch_path;
    EXPECT_TRUE(fs::is_regular_file(scratch_path));
    EXPECT_EQ(fs::file_size(scratch_path), 0u);
    ScratchFile other(path);  // a second one has another name
    EXPECT_NE(other.path(), scratch_path);
    // Installing content read from it at the path leaves the scratch file to the destructor.
    WriteFileAtomically(path, "content");
  }
  EXPECT_FALSE(fs::exists(scratch_path));
  EXPECT_EQ(Entries(), std::vector<std::string>{"video.mp4"});
  const std::string missing = (dir_ / "no_such_dir" / "v.mp4").string();
  EXPECT_HAS(ErrorOf([&] { ScratchFile s(missing); }), "cannot write '" + missing + "'");
}

TEST_F(AtomicFileTest, FailedWriteLeavesThePreviousFileAndNoTemporaries) {
  // A directory is refused before anything is written: no temporary, the directory intact.
  const fs::path target = dir_ / "occupied";
  fs::create_directories(target);
  WriteFileAtomically((target / "keep").string(), "kept");
  const std::string message = ErrorOf([&] { WriteFileAtomically(target.string(), "new"); });
  EXPECT_HAS(message, target.string());
  EXPECT_TRUE(fs::is_directory(target));
  EXPECT_EQ(ReadFile((target / "keep").string()), "kept");
  EXPECT_EQ(Entries(), std::vector<std::string>{"occupied"});
}

TEST_F(AtomicFileTest, ReadOfAMissingFileThrowsNamingThePath) {
  const std::string path = (dir_ / "missing.bin").string();
  const std::string message = ErrorOf([&] { ReadFile(path); });
  EXPECT_HAS(message, path);
}

TEST_F(AtomicFileTest, WrittenFileIsReadableByStandardStreams) {
  const std::string path = (dir_ / "plain.txt").string();
  WriteFileAtomically(path, "line 1\nline 2\n");
  std::ifstream in(path);
  std::string line1, line2;
  std::getline(in, line1);
  std::getline(in, line2);
  EXPECT_EQ(line1, "line 1");
  EXPECT_EQ(line2, "line 2");
}

// ---------------------------------------------------------------------------------------------
// What the output path is: links, devices, FIFOs, directories, sockets; modes; temporaries.

mode_t ModeOf(const fs::path& path) {
  struct stat st {};
  EXPECT_EQ(::lstat(path.c_str(), &st), 0) << path;
  return st.st_mode;
}

void CreateFile(const fs::path& path, const std::string& content, mode_t mode) {
  std::ofstream(path, std::ios::binary) << content;
  ASSERT_EQ(::chmod(path.c_str(), mode), 0);
}

TEST_F(AtomicFileTest, WritesThroughASymlinkKeepingTheLinkAndTheTargetsMode) {
  const fs::path target = dir_ / "target.model";
  CreateFile(target, "old", 0600);
  const fs::path link = dir_ / "link.model";
  fs::create_symlink("target.model", link);  // relative
  WriteFileAtomically(link.string(), "new content");
  EXPECT_TRUE(fs::is_symlink(link));
  EXPECT_EQ(fs::read_symlink(link), "target.model");
  EXPECT_EQ(ReadFile(target.string()), "new content");
  EXPECT_EQ(ModeOf(target) & 07777, 0600u);
  auto names = Entries();
  std::sort(names.begin(), names.end());
  EXPECT_EQ(names, (std::vector<std::string>{"link.model", "target.model"}));
}

TEST_F(AtomicFileTest, WritesThroughAChainOfRelativeSymlinksIntoTheTargetsDirectory) {
  fs::create_directories(dir_ / "a");
  fs::create_directories(dir_ / "b");
  CreateFile(dir_ / "b" / "model", "old", 0640);
  fs::create_symlink("../b/model", dir_ / "a" / "hop");  // relative to a/
  fs::create_symlink("a/hop", dir_ / "out");             // relative to dir_
  WriteFileAtomically((dir_ / "out").string(), "through two links");
  EXPECT_TRUE(fs::is_symlink(dir_ / "out"));
  EXPECT_TRUE(fs::is_symlink(dir_ / "a" / "hop"));
  EXPECT_EQ(ReadFile((dir_ / "b" / "model").string()), "through two links");
  EXPECT_EQ(ModeOf(dir_ / "b" / "model") & 07777, 0640u);
  EXPECT_EQ(std::distance(fs::directory_iterator(dir_ / "a"), fs::directory_iterator()), 1);
  EXPECT_EQ(std::distance(fs::directory_iterator(dir_ / "b"), fs::directory_iterator()), 1);
}

TEST_F(AtomicFileTest, ADanglingSymlinkCreatesItsTarget) {
  fs::create_symlink("created.model", dir_ / "link");
  WriteFileAtomically((dir_ / "link").string(), "fresh");
  EXPECT_TRUE(fs::is_symlink(dir_ / "link"));
  EXPECT_TRUE(fs::is_regular_file(fs::symlink_status(dir_ / "created.model")));
  EXPECT_EQ(ReadFile((dir_ / "created.model").string()), "fresh");
}

TEST_F(AtomicFileTest, ASymlinkToADirectoryIsRefusedAndLeftAlone) {
  fs::create_directories(dir_ / "d");
  fs::create_symlink("d", dir_ / "link");
  const std::string message = ErrorOf([&] { WriteFileAtomically((dir_ / "link").string(), "x"); });
  EXPECT_HAS(message, (dir_ / "link").string());
  EXPECT_HAS(message, "directory");
  EXPECT_TRUE(fs::is_symlink(dir_ / "link"));
  EXPECT_TRUE(fs::is_empty(dir_ / "d"));
}

TEST_F(AtomicFileTest, WritingToDevNullKeepsItACharacterDevice) {
  WriteFileAtomically("/dev/null", "discarded\n");
  EXPECT_TRUE(S_ISCHR(ModeOf("/dev/null")));
}

TEST_F(AtomicFileTest, WritingToACharacterDeviceNodeWritesToTheDevice) {
  // A private null device node, so that a broken implementation cannot damage /dev/null.
  const fs::path node = dir_ / "null";
  if (::mknod(node.c_str(), S_IFCHR | 0666, makedev(1, 3)) != 0)
    GTEST_SKIP() << "cannot create a device node here: " << std::strerror(errno);
  WriteFileAtomically(node.string(), std::string(100000, 'x'));
  EXPECT_TRUE(S_ISCHR(ModeOf(node)));
  EXPECT_EQ(Entries(), std::vector<std::string>{"null"});
}

TEST_F(AtomicFileTest, WritingToAFifoStreamsToItsReader) {
  const fs::path fifo = dir_ / "fifo";
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
  // The reader end is opened first (non-blocking, so this does not wait for a writer); the
  // thread polls it, so it sees the data and then the writer's close (POLLHUP).
  const int reader = ::open(fifo.c_str(), O_RDONLY | O_NONBLOCK | O_CLOEXEC);
  ASSERT_GE(reader, 0);
  std::string received;
  std::thread thread([&] {
    char buf[65536];
    for (;;) {
      pollfd p{reader, POLLIN, 0};
      if (::poll(&p, 1, -1) < 0) continue;
      const ssize_t n = ::read(reader, buf, sizeof buf);
      if (n > 0) received.append(buf, static_cast<std::size_t>(n));
      if (n == 0 && (p.revents & POLLHUP) != 0) break;
    }
  });
  std::string bytes(1000 * 1000, '\0');  // more than a pipe buffer: the writer must block
  for (std::size_t i = 0; i < bytes.size(); ++i) bytes[i] = static_cast<char>(i % 253);
  WriteFileAtomically(fifo.string(), bytes);
  thread.join();
  ::close(reader);
  EXPECT_TRUE(received == bytes) << received.size() << " bytes received";
  EXPECT_TRUE(S_ISFIFO(ModeOf(fifo)));
  EXPECT_EQ(Entries(), std::vector<std::string>{"fifo"});
}

TEST_F(AtomicFileTest, AFifoWithoutAReaderIsAnErrorNotAHang) {
  const fs::path fifo = dir_ / "fifo";
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
  const std::string message = ErrorOf([&] { WriteFileAtomically(fifo.string(), "x"); });
  EXPECT_HAS(message, fifo.string());
  EXPECT_HAS(message, "no process has open for reading");
  EXPECT_EQ(message.find('\n'), std::string::npos);
  EXPECT_TRUE(S_ISFIFO(ModeOf(fifo)));
  EXPECT_EQ(Entries(), std::vector<std::string>{"fifo"});
}

TEST_F(AtomicFileTest, AMagicProcLinkToAPipeWritesIntoThePipe) {
  // /dev/stdout is /proc/self/fd/1, whose readlink is "pipe:[...]", not a path.
  int fds[2];
  ASSERT_EQ(::pipe(fds), 0);
  WriteFileAtomically("/proc/self/fd/" + std::to_string(fds[1]), "via proc");
  ::close(fds[1]);
  char buf[64];
  const ssize_t n = ::read(fds[0], buf, sizeof buf);
  ::close(fds[0]);
  EXPECT_EQ(std::string(buf, n > 0 ? static_cast<std::size_t>(n) : 0), "via proc");
}

TEST_F(AtomicFileTest, ADirectoryIsRefusedNamingThePathAndItsType) {
  fs::create_directories(dir_ / "out");
  const std::string message = ErrorOf([&] { WriteFileAtomically((dir_ / "out").string(), "x"); });
  EXPECT_HAS(message, "'" + (dir_ / "out").string() + "'");
  EXPECT_HAS(message, "it is a directory, not a regular file");
  EXPECT_EQ(message.find('\n'), std::string::npos);
  EXPECT_TRUE(fs::is_directory(dir_ / "out"));
  EXPECT_EQ(Entries(), std::vector<std::string>{"out"});
}

TEST_F(AtomicFileTest, ASocketIsRefusedNamingThePathAndItsType) {
  const fs::path path = dir_ / "sock";
  const int fd = ::socket(AF_UNIX, SOCK_STREAM, 0);
  ASSERT_GE(fd, 0);
  sockaddr_un addr{};
  addr.sun_family = AF_UNIX;
  ASSERT_LT(path.string().size(), sizeof addr.sun_path);
  std::strcpy(addr.sun_path, path.c_str());
  ASSERT_EQ(::bind(fd, reinterpret_cast<const sockaddr*>(&addr), sizeof addr), 0);
  const std::string message = ErrorOf([&] { WriteFileAtomically(path.string(), "x"); });
  ::close(fd);
  EXPECT_HAS(message, path.string());
  EXPECT_HAS(message, "a socket");
  EXPECT_TRUE(S_ISSOCK(ModeOf(path)));
  EXPECT_EQ(Entries(), std::vector<std::string>{"sock"});
}

TEST_F(AtomicFileTest, ReplacingARegularFileKeepsItsModeBits) {
  for (const mode_t mode : {0600u, 0640u, 0755u, 0444u}) {
    const fs::path path = dir_ / ("file" + std::to_string(mode));
    CreateFile(path, "old", mode);
    WriteFileAtomically(path.string(), "new");
    EXPECT_EQ(ModeOf(path) & 07777, mode) << std::oct << mode;
    EXPECT_EQ(ReadFile(path.string()), "new");
  }
}

TEST_F(AtomicFileTest, ANewFileGets0666MaskedByTheUmask) {
  const mode_t old_umask = ::umask(002);
  WriteFileAtomically((dir_ / "new").string(), "x");
  ::umask(old_umask);
  EXPECT_EQ(ModeOf(dir_ / "new") & 07777, 0664u);  // not a fixed 0644
}

TEST_F(AtomicFileTest, StaleTemporariesOfDeadProcessesAreRemovedOthersKept) {
  const pid_t dead = ::fork();
  ASSERT_GE(dead, 0);
  if (dead == 0) ::_exit(0);
  ASSERT_EQ(::waitpid(dead, nullptr, 0), dead);  // reaped: kill(dead, 0) now fails with ESRCH
  ASSERT_NE(::kill(dead, 0), 0);
  const std::string d = std::to_string(dead);
  const std::vector<std::string> stale = {"model.tmp-" + d + "-0", "model.tmp-" + d + "-17"};
  const std::vector<std::string> kept = {
      "model.tmp-" + std::to_string(::getppid()) + "-0",  // a live process (our parent)
      "model.tmp-" + std::to_string(::getpid()) + "-99",  // ours, maybe being written
      "other.tmp-" + d + "-0",                            // another output's temporary
      "model.tmp-" + d + "-x",                            // not our naming scheme
      "model.tmp-" + d,                                   // nor this
      "model"};
  for (const auto& name : stale) CreateFile(dir_ / name, "stale", 0644);
  for (const auto& name : kept) CreateFile(dir_ / name, "keep", 0644);
  WriteFileAtomically((dir_ / "model").string(), "new");
  auto names = Entries();
  std::sort(names.begin(), names.end());
  auto expected = kept;
  std::sort(expected.begin(), expected.end());
  EXPECT_EQ(names, expected);
  EXPECT_EQ(ReadFile((dir_ / "model").string()), "new");
}

TEST_F(AtomicFileTest, AnExceptionBeforeTheRenameRemovesTheTemporary) {
  const std::string path = (dir_ / "model").string();
  WriteFileAtomically(path, "previous");
  std::string seen;
  const std::string message = ErrorOf([&] {
    internal::WriteFileAtomicallyForTest(path, "next", [&](const std::string& tmp) {
      seen = tmp;
      EXPECT_EQ(ReadFile(tmp), "next");
      SECURE_THROW("interrupted '" << path << "'");
    });
  });
  EXPECT_HAS(message, "interrupted");
  EXPECT_FALSE(seen.empty());
  EXPECT_FALSE(fs::exists(seen));
  EXPECT_EQ(ReadFile(path), "previous");
  EXPECT_EQ(Entries(), std::vector<std::string>{"model"});
}

// A child process writes a large file, stops between writing the temporary and the rename, and
// is sent `sig`: the temporary must be gone and the child must have died of `sig`.
void ExpectSignalRemovesTheTemporary(const fs::path& dir, int sig) {
  const std::string path = (dir / "big.csv").string();
  int ready[2];
  ASSERT_EQ(::pipe(ready), 0);
  const pid_t child = ::fork();
  ASSERT_GE(child, 0);
  if (child == 0) {
    ::close(ready[0]);
    try {
      internal::WriteFileAtomicallyForTest(path, std::string(20 * 1000 * 1000, 'x'),
                                           [&](const std::string& tmp) {
                                             const std::string line = tmp + "\n";
                                             if (::write(ready[1], line.data(), line.size()) < 0)
                                               ::_exit(3);
                                             for (;;) ::pause();
                                           });
    } catch (...) {
      ::_exit(2);
    }
    ::_exit(1);
  }
  ::close(ready[1]);
  std::string tmp;
  char c;
  while (::read(ready[0], &c, 1) == 1 && c != '\n') tmp.push_back(c);
  ::close(ready[0]);
  ASSERT_FALSE(tmp.empty()) << "the child did not reach the hook";
  EXPECT_TRUE(fs::exists(tmp)) << tmp;  // paused mid-write: the temporary is there
  ASSERT_EQ(::kill(child, sig), 0);
  int status = 0;
  ASSERT_EQ(::waitpid(child, &status, 0), child);
  EXPECT_TRUE(WIFSIGNALED(status)) << "status " << status;
  if (WIFSIGNALED(status)) {
    EXPECT_EQ(WTERMSIG(status), sig);
  }
  EXPECT_FALSE(fs::exists(tmp)) << tmp;
  EXPECT_FALSE(fs::exists(path));
  EXPECT_TRUE(fs::is_empty(dir));
}

TEST_F(AtomicFileTest, SigtermMidWriteRemovesTheTemporaryAndStillKills) {
  ExpectSignalRemovesTheTemporary(dir_, SIGTERM);
}

TEST_F(AtomicFileTest, SigintMidWriteRemovesTheTemporaryAndStillKills) {
  ExpectSignalRemovesTheTemporary(dir_, SIGINT);
}

TEST_F(AtomicFileTest, RemovePendingTemporaryFilesRemovesTheOneBeingWritten) {
  // What an embedder's own signal handler calls.
  const std::string path = (dir_ / "model").string();
  std::string seen;
  const std::string message = ErrorOf([&] {
    internal::WriteFileAtomicallyForTest(path, "x", [&](const std::string& tmp) {
      seen = tmp;
      ASSERT_TRUE(fs::exists(tmp));
      RemovePendingTemporaryFiles();
      EXPECT_FALSE(fs::exists(tmp));
    });
  });
  EXPECT_HAS(message, path);  // the rename then fails: the temporary is gone
  EXPECT_TRUE(Entries().empty());
}

}  // namespace
}  // namespace secure
