#include "secure/common/progress.h"

#include <chrono>
#include <cstdio>

namespace secure {
namespace {
double Now() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}
}  // namespace

Progress::Progress(std::string label, long total, bool enabled)
    : label_(std::move(label)), total_(total), enabled_(enabled), start_(Now()) {}

void Progress::Update(long done, const std::string& status) {
  if (!enabled_) return;
  const double now = Now();
  if (now - last_print_ < 2.0) return;
  last_print_ = now;
  if (total_ > 0) {
    std::fprintf(stderr, "[%s] %ld/%ld (%.0f%%) %.1fs %s\n", label_.c_str(), done, total_,
                 100.0 * static_cast<double>(done) / static_cast<double>(total_), now - start_,
                 status.c_str());
  } else {
    std::fprintf(stderr, "[%s] %ld %.1fs %s\n", label_.c_str(), done, now - start_, status.c_str());
  }
}

void Progress::Finish(const std::string& status) {
  if (!enabled_) return;
  std::fprintf(stderr, "[%s] done in %.1fs %s\n", label_.c_str(), Now() - start_, status.c_str());
}

}  // namespace secure
