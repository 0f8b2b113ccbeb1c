#pragma once
// Episodes as videos (`secure render`): RGB frames (domains::Frame, from Environment::Render())
// piped as raw rgb24 to the `ffmpeg` command-line tool (Debian package ffmpeg), which encodes them
// with libx264 (H.264, yuv420p, the format every player reads) into an MP4 file; or each frame as
// a PPM image (WritePpm), which needs nothing installed.
//
//   eval::VideoWriter video("episode.mp4", {640, 480, 20});  // starts ffmpeg
//   for (...) video.Write(frame);                            // every frame 640 x 480
//   video.Finish();                                          // episode.mp4 now exists
//
// The output is never half written: ffmpeg writes a scratch file next to it
// ("<path>.tmp-<pid>-<n>", removed on SIGINT/SIGTERM and after a crash like the other
// temporaries, secure/common/atomic_file.h), and only a successful Finish() installs the result
// at `path` with WriteFileAtomically (an existing file there is replaced then, never before; a
// failure leaves it untouched). The encoding is deterministic: the same frames and the same
// ffmpeg give the same bytes (bit-exact flags, no metadata, no encoder timestamps).
#include <sys/types.h>

#include <memory>
#include <string>

#include "secure/common/atomic_file.h"
#include "secure/domains/environment.h"

namespace secure::eval {

struct VideoOptions {
  // Frame size in pixels: even (yuv420p halves the chroma resolution in both directions), at
  // most kMaxVideoSide.
  int width = 640;
  int height = 480;
  int fps = 20;                   // frames per second of playback, 1 to 1000
  std::string ffmpeg = "ffmpeg";  // the encoder binary (looked up on PATH)
  std::string codec = "libx264";  // ffmpeg's -c:v
  /// @throws secure::Error naming the field and value.
  void Validate() const;
};

/// The largest width or height VideoOptions accepts (8K).
inline constexpr int kMaxVideoSide = 8192;

class VideoWriter {
 public:
  /// Validates `options`, checks that `path` is not a directory, creates the scratch file and
  /// starts ffmpeg. @throws secure::Error naming `path` (e.g. "ffmpeg not found").
  VideoWriter(std::string path, VideoOptions options);
  /// Without a successful Finish(): stops ffmpeg and removes the scratch file; `path` is left as
  /// it was.
  ~VideoWriter();
  VideoWriter(const VideoWriter&) = delete;
  VideoWriter& operator=(const VideoWriter&) = delete;

  /// Sends one frame to the encoder. @throws secure::Error if the frame's size is not the
  /// video's, its pixel buffer is not 3 * width * height bytes, or ffmpeg has failed (its
  /// message quoted).
  void Write(const domains::Frame& frame);
  /// Ends the stream, waits for ffmpeg and installs the video at `path`. @throws secure::Error
  /// if no frame was written or ffmpeg failed (its exit status and message quoted).
  void Finish();

  long frames() const { return frames_; }
  const std::string& path() const { return path_; }

 private:
  [[noreturn]] void FailEncoder(const std::string& what);
  int WaitForEncoder();  // closes the stream, waits (once), returns ffmpeg's wait status
  void Stop();

  std::string path_;
  VideoOptions options_;
  std::unique_ptr<ScratchFile> scratch_;  // what ffmpeg writes
  std::unique_ptr<ScratchFile> log_;      // ffmpeg's stderr
  int socket_ = -1;                       // our end of ffmpeg's stdin
  pid_t pid_ = -1;
  int status_ = 0;  // ffmpeg's wait status, once reaped
  long frames_ = 0;
  bool finished_ = false;
};

/// Writes `frame` as a binary PPM image (P6) with WriteFileAtomically. @throws secure::Error
/// naming the path if the frame is inconsistent or the file cannot be written.
void WritePpm(const std::string& path, const domains::Frame& frame);

}  // namespace secure::eval
