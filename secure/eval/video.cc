#include "secure/eval/video.h"

#include <fcntl.h>
#include <signal.h>
#include <spawn.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <string_view>
#include <utility>
#include <vector>

#include "secure/common/error.h"
#include "secure/common/excerpt.h"

extern char** environ;

namespace secure::eval {
namespace {

// The first non-empty line of ffmpeg's log, for a one-line error message.
std::string FirstLine(const std::string& log) {
  std::size_t begin = 0;
  while (begin < log.size()) {
    std::size_t end = log.find('\n', begin);
    if (end == std::string::npos) end = log.size();
    std::string_view line(log.data() + begin, end - begin);
    while (!line.empty() && (line.back() == '\r' || line.back() == ' ')) line.remove_suffix(1);
    if (!line.empty()) return std::string(line);
    begin = end + 1;
  }
  return "";
}

std::string StatusText(int status) {
  if (WIFEXITED(status)) return "exit status " + std::to_string(WEXITSTATUS(status));
  if (WIFSIGNALED(status)) return "killed by signal " + std::to_string(WTERMSIG(status));
  return "wait status " + std::to_string(status);
}

void CheckFrame(const domains::Frame& frame, const std::string& what) {
  SECURE_CHECK(frame.width > 0 && frame.height > 0, what << ": the frame is " << frame.width
                                                         << " x " << frame.height
                                                         << ", must be positive");
  SECURE_CHECK(frame.rgb.size() == 3 * static_cast<std::size_t>(frame.width) *
                                       static_cast<std::size_t>(frame.height),
               what << ": the frame's pixel buffer has " << frame.rgb.size()
                    << " bytes, expected 3 x " << frame.width << " x " << frame.height);
}

}  // namespace

void VideoOptions::Validate() const {
  SECURE_CHECK(width > 0 && width <= kMaxVideoSide && width % 2 == 0,
               "video width = " << width << ", must be even and in [2, " << kMaxVideoSide
                                << "] (H.264 yuv420p)");
  SECURE_CHECK(height > 0 && height <= kMaxVideoSide && height % 2 == 0,
               "video height = " << height << ", must be even and in [2, " << kMaxVideoSide
                                 << "] (H.264 yuv420p)");
  SECURE_CHECK(fps >= 1 && fps <= 1000, "video fps = " << fps << ", must be in [1, 1000]");
  SECURE_CHECK(!ffmpeg.empty(), "video ffmpeg: empty program name");
  SECURE_CHECK(!codec.empty(), "video codec: empty name");
}

VideoWriter::VideoWriter(std::string path, VideoOptions options)
    : path_(std::move(path)), options_(std::move(options)) {
  options_.Validate();
  SECURE_CHECK(!path_.empty(), "cannot write '': empty file name");
  struct stat st {};
  SECURE_CHECK(::stat(path_.c_str(), &st) != 0 || !S_ISDIR(st.st_mode),
               "cannot write '" << path_ << "': it is a directory");
  scratch_ = std::make_unique<ScratchFile>(path_);
  log_ = std::make_unique<ScratchFile>(path_);

  int fds[2];
  SECURE_CHECK(::socketpair(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0, fds) == 0,
               "cannot write '" << path_ << "': socketpair: " << std::strerror(errno));
  socket_ = fds[0];
  const int child_end = fds[1];
  const std::string size = std::to_string(options_.width) + "x" + std::to_string(options_.height);
  const std::vector<std::string> args = {options_.ffmpeg,
                                         "-nostdin",
                                         "-hide_banner",
                                         "-loglevel",
                                         "error",
                                         "-f",
                                         "rawvideo",
                                         "-pix_fmt",
                                         "rgb24",
                                         "-s",
                                         size,
                                         "-r",
                                         std::to_string(options_.fps),
                                         "-i",
                                         "pipe:0",
                                         "-an",
                                         "-c:v",
                                         options_.codec,
                                         "-pix_fmt",
                                         "yuv420p",
                                         "-fflags",
                                         "+bitexact",
                                         "-flags:v",
                                         "+bitexact",
                                         "-map_metadata",
                                         "-1",
                                         "-f",
                                         "mp4",
                                         "-y",
                                         scratch_->path()};
  std::vector<char*> argv;
  for (const std::string& a : args) argv.push_back(const_cast<char*>(a.c_str()));
  argv.push_back(nullptr);

  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  posix_spawn_file_actions_adddup2(&actions, child_end, 0);
  posix_spawn_file_actions_addopen(&actions, 1, "/dev/null", O_WRONLY, 0);
  posix_spawn_file_actions_addopen(&actions, 2, log_->path().c_str(), O_WRONLY | O_TRUNC, 0);
  // ffmpeg reads -nostdin as "no interaction on stdin"; the frames come from pipe:0 all the same.
  const int spawned =
      ::posix_spawnp(&pid_, options_.ffmpeg.c_str(), &actions, nullptr, argv.data(), environ);
  posix_spawn_file_actions_destroy(&actions);
  ::close(child_end);
  if (spawned != 0) {
    pid_ = -1;
    ::close(socket_);
    socket_ = -1;
    SECURE_CHECK(spawned != ENOENT,
                 "cannot write '" << path_ << "': " << options_.ffmpeg
                                  << " not found (install ffmpeg, the Debian package ffmpeg)");
    SECURE_THROW("cannot write '" << path_ << "': cannot start " << options_.ffmpeg << ": "
                                  << std::strerror(spawned));
  }
}

VideoWriter::~VideoWriter() { Stop(); }

void VideoWriter::Stop() {
  if (socket_ >= 0) {
    ::close(socket_);
    socket_ = -1;
  }
  if (pid_ > 0) {
    if (!finished_) ::kill(pid_, SIGKILL);
    int status = 0;
    while (::waitpid(pid_, &status, 0) < 0 && errno == EINTR) {
    }
    pid_ = -1;
  }
}

int VideoWriter::WaitForEncoder() {
  if (socket_ >= 0) {
    ::close(socket_);  // end of stream: ffmpeg finishes the file
    socket_ = -1;
  }
  if (pid_ > 0) {
    int status = 0;
    while (::waitpid(pid_, &status, 0) < 0) {
      SECURE_CHECK(errno == EINTR,
                   "cannot write '" << path_ << "': waitpid: " << std::strerror(errno));
    }
    pid_ = -1;
    status_ = status;
  }
  return status_;
}

void VideoWriter::FailEncoder(const std::string& what) {
  const int status = WaitForEncoder();
  std::string message;
  try {
    message = FirstLine(ReadFile(log_->path()));
  } catch (const Error&) {
  }
  SECURE_THROW("cannot write '" << path_ << "': " << options_.ffmpeg << " failed (" << what
                                << (status != 0 ? ", " + StatusText(status) : std::string()) << ")"
                                << (message.empty() ? "" : ": ") << Excerpt(message, 200));
}

void VideoWriter::Write(const domains::Frame& frame) {
  SECURE_CHECK(!finished_ && socket_ >= 0,
               "cannot write '" << path_ << "': the video is finished or has failed");
  const std::string what = "cannot write '" + path_ + "': frame " + std::to_string(frames_);
  CheckFrame(frame, what);
  SECURE_CHECK(frame.width == options_.width && frame.height == options_.height,
               what << " is " << frame.width << " x " << frame.height << ", the video's frames are "
                    << options_.width << " x " << options_.height);
  const auto* data = reinterpret_cast<const char*>(frame.rgb.data());
  std::size_t left = frame.rgb.size();
  while (left > 0) {
    // MSG_NOSIGNAL: an encoder that died is an EPIPE error here, not a SIGPIPE killing us.
    const ssize_t n = ::send(socket_, data, left, MSG_NOSIGNAL);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) {
      const int error = errno;
      ::close(socket_);
      socket_ = -1;
      FailEncoder(n < 0 && (error == EPIPE || error == ECONNRESET)
                      ? "it stopped reading frames at frame " + std::to_string(frames_)
                      : std::string("sending frame ") + std::to_string(frames_) + ": " +
                            std::strerror(error));
    }
    data += n;
    left -= static_cast<std::size_t>(n);
  }
  ++frames_;
}

void VideoWriter::Finish() {
  SECURE_CHECK(!finished_, "cannot write '" << path_ << "': the video is already finished");
  SECURE_CHECK(frames_ > 0, "cannot write '" << path_ << "': no frames");
  SECURE_CHECK(socket_ >= 0 && pid_ > 0, "cannot write '" << path_ << "': the encoder has failed");
  const int status = WaitForEncoder();
  if (!WIFEXITED(status) || WEXITSTATUS(status) != 0) FailEncoder("at the end of the stream");
  const std::string bytes = ReadFile(scratch_->path());
  SECURE_CHECK(!bytes.empty(), "cannot write '" << path_ << "': " << options_.ffmpeg
                                                << " exited with 0 but wrote nothing");
  WriteFileAtomically(path_, bytes);
  finished_ = true;
  scratch_.reset();
  log_.reset();
}

void WritePpm(const std::string& path, const domains::Frame& frame) {
  CheckFrame(frame, "cannot write '" + path + "'");
  std::string bytes =
      "P6\n" + std::to_string(frame.width) + " " + std::to_string(frame.height) + "\n255\n";
  bytes.append(reinterpret_cast<const char*>(frame.rgb.data()), frame.rgb.size());
  WriteFileAtomically(path, bytes);
}

}  // namespace secure::eval
