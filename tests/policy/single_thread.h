#pragma once
// Training runs with one thread, as the SECURE pipeline configures it: one LibTorch intra-op
// thread, and one OpenBLAS thread. LibTorch here uses OpenBLAS (pthreads build) for matrix
// products, and at::set_num_threads does not reach it: left at its default (one thread per
// core), concurrent trainers in different std::threads slow each other down ~6x (measured), and
// results depend on OpenBLAS's thread count. openblas_set_num_threads is looked up at run time
// so that nothing breaks with another BLAS.
#include <ATen/Parallel.h>
#include <dlfcn.h>

namespace secure::policy::test {

inline bool UseOneTrainingThread() {
  at::set_num_threads(1);
  using SetThreads = void (*)(int);
  if (auto* set = reinterpret_cast<SetThreads>(dlsym(RTLD_DEFAULT, "openblas_set_num_threads")))
    set(1);
  return true;
}

}  // namespace secure::policy::test
