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

}  // namespace secure::nn
