#include "secure/common/progress.h"

#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdarg>
#include <iostream>
#include <vector>

namespace secure {
namespace {

std::mutex g_installed_mutex;
ProgressLine* g_installed = nullptr;

}  // namespace

ProgressLine::ProgressLine(std::ostream* out, bool live, double min_redraw_seconds)
    : out_(out), live_(live), min_redraw_seconds_(min_redraw_seconds) {}

ProgressLine::~ProgressLine() {
  Uninstall();
  Finish();
}

bool ProgressLine::IsTerminal(std::FILE* stream) {
  return stream != nullptr && isatty(fileno(stream)) == 1;
}

bool ProgressLine::Live(ProgressMode mode, std::FILE* stream) {
  switch (mode) {
    case ProgressMode::kAlways:
      return true;
    case ProgressMode::kNever:
      return false;
    case ProgressMode::kAuto:
      break;
  }
  return IsTerminal(stream);
}

void ProgressLine::Start(long total, const std::string& label, long done) {
  const std::lock_guard<std::mutex> lock(mutex_);
  label_ = label;
  total_ = std::max(0L, total);
  done_ = std::max(0L, done);
  done_at_start_ = done_;
  started_ = true;
  start_ = Clock::now();
  DrawLocked(true);
}

void ProgressLine::AddTotal(long n) {
  const std::lock_guard<std::mutex> lock(mutex_);
  total_ += n;
  DrawLocked(false);
}

void ProgressLine::Advance(long n) {
  const std::lock_guard<std::mutex> lock(mutex_);
  done_ += n;
  DrawLocked(false);
}

void ProgressLine::Milestone(const std::string& line) {
  if (out_ == nullptr) return;
  const std::lock_guard<std::mutex> lock(mutex_);
  const bool redraw = drawn_;
  ClearLocked();
  *out_ << line << std::endl;
  if (redraw) DrawLocked(true);
}

void ProgressLine::Finish() {
  const std::lock_guard<std::mutex> lock(mutex_);
  ClearLocked();
  started_ = false;
}

long ProgressLine::done() const {
  const std::lock_guard<std::mutex> lock(mutex_);
  return done_;
}

long ProgressLine::total() const {
  const std::lock_guard<std::mutex> lock(mutex_);
  return total_;
}

std::string ProgressLine::Duration(double seconds) {
  const long s = std::max(0L, static_cast<long>(std::lround(seconds)));
  char buffer[48];
  if (s >= 3600) {
    std::snprintf(buffer, sizeof buffer, "%ld:%02ld:%02ld", s / 3600, s / 60 % 60, s % 60);
  } else {
    std::snprintf(buffer, sizeof buffer, "%ld:%02ld", s / 60, s % 60);
  }
  return buffer;
}

std::string ProgressLine::Format(const std::string& label, long done, long total, double elapsed,
                                 long done_since_start) {
  std::string line = label + ": " + std::to_string(done) + "/" + std::to_string(total);
  if (total > 0) {
    const long percent = std::min(100L, 100 * std::max(0L, done) / total);
    line += " (" + std::to_string(percent) + "%)";
  }
  line += ", " + Duration(elapsed) + " elapsed, ";
  if (done_since_start > 0 && total >= done) {
    const double per_unit = elapsed / static_cast<double>(done_since_start);
    line += "~" + Duration(per_unit * static_cast<double>(total - done)) + " left";
  } else {
    line += "--:-- left";
  }
  return line;
}

void ProgressLine::DrawLocked(bool force) {
  if (!live() || !started_) return;
  const Clock::time_point now = Clock::now();
  if (!force && drawn_ &&
      std::chrono::duration<double>(now - last_draw_).count() < min_redraw_seconds_)
    return;
  last_draw_ = now;
  const std::string text =
      Format(label_, done_, total_, std::chrono::duration<double>(now - start_).count(),
             done_ - done_at_start_);
  *out_ << '\r' << text;
  if (text.size() < drawn_width_) *out_ << std::string(drawn_width_ - text.size(), ' ');
  out_->flush();
  drawn_ = true;
  drawn_width_ = std::max(drawn_width_, text.size());
}

void ProgressLine::ClearLocked() {
  if (!drawn_ || out_ == nullptr) return;
  *out_ << '\r' << std::string(drawn_width_, ' ') << '\r';
  out_->flush();
  drawn_ = false;
  drawn_width_ = 0;
}

void ProgressLine::Install() {
  const std::lock_guard<std::mutex> lock(g_installed_mutex);
  g_installed = this;
}

void ProgressLine::Uninstall() {
  const std::lock_guard<std::mutex> lock(g_installed_mutex);
  if (g_installed == this) g_installed = nullptr;
}

void PrintStatusLine(const std::string& line) {
  const std::lock_guard<std::mutex> lock(g_installed_mutex);
  if (g_installed != nullptr && g_installed->live()) {
    g_installed->Milestone(line);
  } else {
    std::fputs((line + "\n").c_str(), stderr);
  }
}

void PrintStatusLineF(const char* format, ...) {
  std::va_list args;
  va_start(args, format);
  std::va_list copy;
  va_copy(copy, args);
  const int n = std::vsnprintf(nullptr, 0, format, copy);
  va_end(copy);
  std::string line;
  if (n > 0) {
    std::vector<char> buffer(static_cast<std::size_t>(n) + 1);
    std::vsnprintf(buffer.data(), buffer.size(), format, args);
    line.assign(buffer.data(), static_cast<std::size_t>(n));
  }
  va_end(args);
  if (!line.empty() && line.back() == '\n') line.pop_back();
  PrintStatusLine(line);
}

}  // namespace secure
