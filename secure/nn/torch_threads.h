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

/// Sets LibTorch's (this thread's) and OpenBLAS's (process-wide) thread counts for a scope and
/// restores them on exit. The one guard of the trainers that take a `threads` option. Scopes on
/// several threads at once share OpenBLAS's count: the first sets it, the last restores it, and
/// each training runs on that count throughout (its bytes do not depend on when another ends).
/// @throws secure::Error if threads <= 0, or if it differs from the count concurrent scopes hold.
class ScopedTorchThreads {
 public:
  explicit ScopedTorchThreads(int threads);
  ~ScopedTorchThreads();
  ScopedTorchThreads(const ScopedTorchThreads&) = delete;
  ScopedTorchThreads& operator=(const ScopedTorchThreads&) = delete;

 private:
  int previous_torch_;
};

}  // namespace secure::nn
