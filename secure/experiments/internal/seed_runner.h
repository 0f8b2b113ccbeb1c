#pragma once
// Pieces of the experiment driver (experiment.cc, user_study.cc, label_efficiency.cc):
// serialised progress lines and a pool that runs one job per seed on a few threads. INTERNAL:
// include only from secure/experiments/*.cc.
#include <algorithm>
#include <atomic>
#include <exception>
#include <functional>
#include <ostream>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "secure/common/error.h"
#include "secure/common/progress.h"
#include "secure/nn/torch_threads.h"

namespace secure::experiments::internal {

/// Progress lines ("[seed 3] ...") written whole, one at a time, from any thread, above the live
/// line of a ProgressLine (common/progress.h) that counts the experiment's work units.
class Progress {
 public:
  Progress(ProgressLine* line, bool enabled) : line_(enabled ? line : nullptr) {}
  template <typename F>
  void Line(F&& write) {
    if (line_ == nullptr) return;
    std::ostringstream line;
    write(line);
    line_->Milestone(line.str());
  }
  void Start(long total, const std::string& label) {
    if (line_ != nullptr) line_->Start(total, label);
  }
  void Advance(long n = 1) {
    if (line_ != nullptr && n > 0) line_->Advance(n);
  }
  void AddTotal(long n) {
    if (line_ != nullptr && n > 0) line_->AddTotal(n);
  }
  void Finish() {
    if (line_ != nullptr) line_->Finish();
  }

 private:
  ProgressLine* line_;
};

/// Runs job(i) for i = 0 .. count - 1 on `threads` workers (the calling thread is one of them),
/// each worker taking the next index; LibTorch and OpenBLAS run one thread per worker. The
/// first failure stops the remaining jobs and is rethrown as "<label> <first_label + i>: what"
/// (as it is when `label` is null).
inline void RunJobsInParallel(int count, int threads, const std::function<void(int)>& job,
                              const char* label, long first_label) {
  std::vector<std::exception_ptr> errors(static_cast<std::size_t>(count));
  std::atomic<int> next{0};
  std::atomic<bool> failed{false};
  auto worker = [&] {
    nn::SetTorchThreads(1);  // per thread (OpenMP): parallelism comes from the jobs
    for (int i = next++; i < count && !failed; i = next++) {
      try {
        job(i);
      } catch (...) {
        errors[static_cast<std::size_t>(i)] = std::current_exception();
        failed = true;
      }
    }
  };
  const int workers = std::max(1, std::min(threads, count));
  std::vector<std::thread> pool;
  for (int t = 1; t < workers; ++t) pool.emplace_back(worker);
  worker();
  for (std::thread& t : pool) t.join();
  for (int i = 0; i < count; ++i) {
    if (!errors[static_cast<std::size_t>(i)]) continue;
    try {
      std::rethrow_exception(errors[static_cast<std::size_t>(i)]);
    } catch (const std::exception& e) {
      if (label == nullptr) SECURE_THROW(e.what());
      SECURE_THROW(label << " " << first_label + i << ": " << e.what());
    }
  }
}

}  // namespace secure::experiments::internal
