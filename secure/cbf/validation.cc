#include "secure/cbf/validation.h"

#include <algorithm>
#include <exception>
#include <thread>
#include <vector>

#include "secure/common/error.h"

namespace secure::cbf {
namespace {
double Ratio(long a, long b) {
  return b > 0 ? static_cast<double>(a) / static_cast<double>(b) : 0.0;
}
}  // namespace

ClassAccuracy EvaluateAccuracy(Barrier& barrier, const Eigen::Ref<const Eigen::MatrixXf>& safe,
                               const Eigen::Ref<const Eigen::MatrixXf>& near_dangerous) {
  ClassAccuracy acc;
  Eigen::VectorXf h(safe.cols());
  barrier.Evaluate(safe, h);
  if (safe.cols() > 0) acc.safe = (h.array() >= 0.0f).cast<double>().mean();
  h.resize(near_dangerous.cols());
  barrier.Evaluate(near_dangerous, h);
  if (near_dangerous.cols() > 0) acc.near_dangerous = (h.array() < 0.0f).cast<double>().mean();
  return acc;
}

double Confusion::SafeCorrect() const { return Ratio(safe_as_safe, truly_safe()); }
double Confusion::OverConservative() const { return Ratio(safe_as_unsafe, truly_safe()); }
double Confusion::UnderConservative() const { return Ratio(unsafe_as_safe, truly_unsafe()); }
double Confusion::UnsafeCorrect() const { return Ratio(unsafe_as_unsafe, truly_unsafe()); }

Confusion& Confusion::operator+=(const Confusion& o) {
  safe_as_safe += o.safe_as_safe;
  safe_as_unsafe += o.safe_as_unsafe;
  unsafe_as_safe += o.unsafe_as_safe;
  unsafe_as_unsafe += o.unsafe_as_unsafe;
  return *this;
}

nlohmann::json Confusion::ToJson() const {
  return {{"counts",
           {{"safe_as_safe", safe_as_safe},
            {"safe_as_unsafe", safe_as_unsafe},
            {"unsafe_as_safe", unsafe_as_safe},
            {"unsafe_as_unsafe", unsafe_as_unsafe}}},
          {"states", total()},
          {"truly_safe", truly_safe()},
          {"truly_unsafe", truly_unsafe()},
          {"safe_correct", SafeCorrect()},
          {"over_conservative", OverConservative()},
          {"under_conservative", UnderConservative()},
          {"unsafe_correct", UnsafeCorrect()}};
}

Confusion ValidateOnGrid(const std::function<std::unique_ptr<Barrier>()>& make_barrier,
                         const std::function<std::unique_ptr<Barrier>()>& make_reference,
                         const StateSource& source, const GridValidationOptions& options) {
  SECURE_CHECK(options.threads > 0,
               "GridValidationOptions::threads = " << options.threads << ", must be > 0");
  SECURE_CHECK(options.chunk > 0,
               "GridValidationOptions::chunk = " << options.chunk << ", must be > 0");
  SECURE_CHECK(source.state_dim > 0 && source.size >= 0 && source.fill,
               "ValidateOnGrid: the state source (" << source.size << " states of dimension "
                                                    << source.state_dim << ") is not usable");
  const long total = source.size;
  const int threads = static_cast<int>(std::min<long>(options.threads, std::max(1L, total / 1024)));
  // Evaluators are made on this thread (the factories need not be thread safe).
  std::vector<std::unique_ptr<Barrier>> barriers, references;
  for (int t = 0; t < threads; ++t) {
    barriers.push_back(make_barrier());
    references.push_back(make_reference());
    for (const Barrier* b : {barriers.back().get(), references.back().get()}) {
      SECURE_CHECK(b->state_dim() == source.state_dim,
                   b->Describe() << " takes " << b->state_dim()
                                 << "-dimensional states; the grid's states have "
                                 << source.state_dim);
    }
  }
  std::vector<Confusion> partial(threads);
  std::vector<std::exception_ptr> errors(threads);
  auto work = [&](int t) {
    try {
      // Contiguous slices: thread t takes [t*total/threads, (t+1)*total/threads).
      const long begin = total * t / threads, end = total * (t + 1) / threads;
      Eigen::MatrixXf states(source.state_dim, options.chunk);
      Eigen::VectorXf h(options.chunk), truth(options.chunk);
      Confusion c;
      for (long first = begin; first < end; first += options.chunk) {
        const long n = std::min(options.chunk, end - first);
        source.fill(first, n, states.leftCols(n));
        barriers[t]->Evaluate(states.leftCols(n), h.head(n));
        references[t]->Evaluate(states.leftCols(n), truth.head(n));
        for (long i = 0; i < n; ++i) {
          const bool truly_safe = truth[i] >= 0.0f;
          const bool predicted_safe = h[i] >= 0.0f;
          if (truly_safe) {
            ++(predicted_safe ? c.safe_as_safe : c.safe_as_unsafe);
          } else {
            ++(predicted_safe ? c.unsafe_as_safe : c.unsafe_as_unsafe);
          }
        }
      }
      partial[t] = c;
    } catch (...) {
      errors[t] = std::current_exception();  // rethrown on the calling thread below
    }
  };
  std::vector<std::thread> pool;
  for (int t = 1; t < threads; ++t) pool.emplace_back(work, t);
  work(0);
  for (auto& th : pool) th.join();
  for (const auto& e : errors)
    if (e) std::rethrow_exception(e);
  Confusion result;
  for (const auto& c : partial) result += c;
  return result;
}

}  // namespace secure::cbf
