#pragma once
// LibTorch's intra-op thread count, without including <torch/torch.h> (defined in
// torch_mlp.cc; link secure::nn_torch). With the OpenMP backend the setting belongs to the
// calling thread: call it in every thread that trains.
namespace secure::nn {

/// Sets LibTorch's intra-op threads for the calling thread (> 0), and OpenBLAS's thread count
/// (process-wide) when OpenBLAS is the BLAS in use.
void SetTorchThreads(int threads);
/// The current intra-op thread count of the calling thread.
int TorchThreads();
/// OpenBLAS's current thread count, or 0 when OpenBLAS is not the BLAS in use.
int BlasThreads();

/// Sets LibTorch's and OpenBLAS's thread counts for a scope (SetTorchThreads) and restores
/// both previous counts on exit. The one guard of the trainers that take a `threads` option.
class ScopedTorchThreads {
 public:
  explicit ScopedTorchThreads(int threads);
  ~ScopedTorchThreads();
  ScopedTorchThreads(const ScopedTorchThreads&) = delete;
  ScopedTorchThreads& operator=(const ScopedTorchThreads&) = delete;

 private:
  int previous_torch_;
  int previous_blas_;  // 0: no OpenBLAS, nothing to restore
};

}  // namespace secure::nn
