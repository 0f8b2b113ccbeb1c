// The video writer: synthetic frames through ffmpeg into an MP4 that ffprobe reads back; bad
// frames and failing encoders are errors that never leave a half file nor touch an existing one.
#include "secure/eval/video.h"

#include <gtest/gtest.h>

#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <string>

#include "secure/common/atomic_file.h"
#include "tests/test_util.h"

namespace secure::eval {
namespace {

using test::ErrorOf;

bool HaveFfmpeg() {
  return std::system("command -v ffmpeg >/dev/null 2>&1 && command -v ffprobe >/dev/null 2>&1") ==
         0;
}

#define SKIP_WITHOUT_FFMPEG()                                                                   \
  if (!HaveFfmpeg())                                                                            \
  GTEST_SKIP() << "ffmpeg/ffprobe not installed (scripts/setup.sh installs the Debian package " \
                  "ffmpeg)"

// A moving gradient, different in every frame.
domains::Frame Synthetic(int width, int height, int t) {
  domains::Frame f;
  f.width = width;
  f.height = height;
  f.rgb.resize(3 * static_cast<std::size_t>(width) * height);
  for (int y = 0; y < height; ++y)
    for (int x = 0; x < width; ++x) {
      std::uint8_t* p = &f.rgb[3 * (static_cast<std::size_t>(y) * width + x)];
      p[0] = static_cast<std::uint8_t>(4 * x + 8 * t);
      p[1] = static_cast<std::uint8_t>(4 * y);
      p[2] = static_cast<std::uint8_t>(128 + 16 * t);
    }
  return f;
}

std::string Run(const std::string& command) {
  std::string out;
  FILE* pipe = ::popen(command.c_str(), "r");
  if (pipe == nullptr) return out;
  char buffer[256];
  while (std::fgets(buffer, sizeof buffer, pipe) != nullptr) out += buffer;
  ::pclose(pipe);
  return out;
}

// "width,height,frames" as ffprobe counts them.
std::string Probe(const std::string& path) {
  std::string s =
      Run("ffprobe -v error -count_frames -select_streams v:0 -show_entries "
          "stream=nb_read_frames,width,height -of csv=p=0 '" +
          path + "'");
  while (!s.empty() && (s.back() == '\n' || s.back() == '\r')) s.pop_back();
  return s;
}

class VideoWriterTest : public test::TempDirTest {
 protected:
  // The names in the test directory (temporaries included).
  std::vector<std::string> Names() const {
    std::vector<std::string> names;
    for (const auto& e : std::filesystem::directory_iterator(dir_))
      names.push_back(e.path().filename().string());
    std::sort(names.begin(), names.end());
    return names;
  }
};

TEST_F(VideoWriterTest, WritesAnMp4WithEveryFrame) {
  SKIP_WITHOUT_FFMPEG();
  const std::string path = PathOf("episode.mp4");
  VideoWriter video(path, VideoOptions{64, 48, 10});
  for (int t = 0; t < 7; ++t) video.Write(Synthetic(64, 48, t));
  EXPECT_FALSE(std::filesystem::exists(path));  // nothing at the path before Finish()
  video.Finish();
  EXPECT_EQ(video.frames(), 7);
  EXPECT_EQ(Probe(path), "64,48,7");
  EXPECT_EQ(Names(), std::vector<std::string>{"episode.mp4"});  // no temporaries left
}

TEST_F(VideoWriterTest, TheSameFramesGiveTheSameBytes) {
  SKIP_WITHOUT_FFMPEG();
  for (const char* name : {"a.mp4", "b.mp4"}) {
    VideoWriter video(PathOf(name), VideoOptions{32, 16, 20});
    for (int t = 0; t < 5; ++t) video.Write(Synthetic(32, 16, t));
    video.Finish();
  }
  EXPECT_EQ(ReadFile(PathOf("a.mp4")), ReadFile(PathOf("b.mp4")));
}

TEST_F(VideoWriterTest, ReplacesAnExistingFileOnSuccess) {
  SKIP_WITHOUT_FFMPEG();
  const std::string path = Write("episode.mp4", "old");
  VideoWriter video(path, VideoOptions{16, 16, 5});
  video.Write(Synthetic(16, 16, 0));
  EXPECT_EQ(ReadFile(path), "old");
  video.Finish();
  EXPECT_EQ(Probe(path), "16,16,1");
}

TEST_F(VideoWriterTest, AnOddSizeIsAnError) {
  EXPECT_HAS(ErrorOf([&] {
               VideoWriter(PathOf("v.mp4"), VideoOptions{63, 48, 10});
             }),
             "video width = 63, must be even");
  EXPECT_HAS(ErrorOf([&] {
               VideoWriter(PathOf("v.mp4"), VideoOptions{64, 47, 10});
             }),
             "video height = 47, must be even");
  EXPECT_HAS(ErrorOf([&] { VideoOptions{64, 48, 0}.Validate(); }), "video fps = 0");
  EXPECT_TRUE(Names().empty());
}

TEST_F(VideoWriterTest, AFrameOfAnotherSizeIsAnErrorAndNothingIsWritten) {
  SKIP_WITHOUT_FFMPEG();
  const std::string path = PathOf("v.mp4");
  {
    VideoWriter video(path, VideoOptions{64, 48, 10});
    video.Write(Synthetic(64, 48, 0));
    const std::string e = ErrorOf([&] { video.Write(Synthetic(32, 24, 1)); });
    EXPECT_HAS(e, path);
    EXPECT_HAS(e, "frame 1 is 32 x 24, the video's frames are 64 x 48");
    domains::Frame short_buffer = Synthetic(64, 48, 1);
    short_buffer.rgb.resize(10);
    EXPECT_HAS(ErrorOf([&] { video.Write(short_buffer); }), "pixel buffer has 10 bytes");
  }  // destroyed without Finish()
  EXPECT_TRUE(Names().empty());
}

TEST_F(VideoWriterTest, AFailingEncoderLeavesTheExistingFileUntouched) {
  SKIP_WITHOUT_FFMPEG();
  const std::string path = Write("v.mp4", "old");
  VideoOptions options{16, 16, 10};
  options.codec = "no-such-codec";
  const std::string e = ErrorOf([&] {
    VideoWriter video(path, options);
    for (int t = 0; t < 50; ++t) video.Write(Synthetic(16, 16, t));
    video.Finish();
  });
  EXPECT_HAS(e, "cannot write '" + path + "': ffmpeg failed");
  EXPECT_HAS(e, "exit status");
  EXPECT_HAS(e, "no-such-codec");  // ffmpeg's own message is quoted
  EXPECT_EQ(e.find('\n'), std::string::npos);
  EXPECT_EQ(ReadFile(path), "old");
  EXPECT_EQ(Names(), std::vector<std::string>{"v.mp4"});
}

TEST_F(VideoWriterTest, AMissingEncoderIsAnErrorNamingThePath) {
  const std::string path = Write("v.mp4", "old");
  VideoOptions options{16, 16, 10};
  options.ffmpeg = PathOf("no-ffmpeg-here");
  const std::string e = ErrorOf([&] { VideoWriter video(path, options); });
  EXPECT_HAS(e, "cannot write '" + path + "'");
  EXPECT_HAS(e, "not found (install ffmpeg");
  EXPECT_EQ(ReadFile(path), "old");
  EXPECT_EQ(Names(), std::vector<std::string>{"v.mp4"});
}

TEST_F(VideoWriterTest, AMissingDirectoryOrADirectoryIsAnError) {
  const std::string missing = PathOf("no/such/dir/v.mp4");
  EXPECT_HAS(ErrorOf([&] {
               VideoWriter video(missing, VideoOptions{16, 16, 10});
             }),
             "cannot write '" + missing + "'");
  std::filesystem::create_directory(PathOf("d"));
  EXPECT_HAS(ErrorOf([&] {
               VideoWriter video(PathOf("d"), VideoOptions{16, 16, 10});
             }),
             "it is a directory");
  EXPECT_EQ(Names(), std::vector<std::string>{"d"});
}

TEST_F(VideoWriterTest, FinishWithoutFramesIsAnError) {
  SKIP_WITHOUT_FFMPEG();
  const std::string path = PathOf("v.mp4");
  {
    VideoWriter video(path, VideoOptions{16, 16, 10});
    EXPECT_HAS(ErrorOf([&] { video.Finish(); }), "no frames");
  }
  EXPECT_TRUE(Names().empty());
}

TEST_F(VideoWriterTest, WritePpm) {
  const domains::Frame f = Synthetic(3, 2, 0);
  WritePpm(PathOf("f.ppm"), f);
  const std::string bytes = ReadFile(PathOf("f.ppm"));
  EXPECT_EQ(bytes, "P6\n3 2\n255\n" + std::string(f.rgb.begin(), f.rgb.end()));
  domains::Frame bad = f;
  bad.rgb.pop_back();
  EXPECT_HAS(ErrorOf([&] { WritePpm(PathOf("g.ppm"), bad); }), "pixel buffer has 17 bytes");
}

}  // namespace
}  // namespace secure::eval
