#pragma once
// The network architectures the benchmarks use, in one place so that every program measures the
// same nets. Weights are random (nn::RandomMlpParams): inference cost does not depend on them.

#include <string>
#include <vector>

#include "secure/nn/mlp.h"

namespace secure::bench {

/// Double integrator (paper Table 1): 4 -> 64 -> 64 -> 64 -> 1, tanh (BarrierTrainerOptions
/// defaults).
inline nn::MlpSpec DoubleIntegratorSpec() { return {4, {64, 64, 64}, 1, nn::Activation::kTanh}; }

/// Derby-sized per-obstacle barrier: 4 -> 64 -> 128 -> 64 -> 1, relu. The shield evaluates it once
/// per (state, obstacle) pair, so a batch of M states is M x kDerbyObstacles network inputs.
inline constexpr int kDerbyObstacles = 12;
inline nn::MlpSpec DerbySpec() { return {4, {64, 128, 64}, 1, nn::Activation::kRelu}; }

/// Panda-sized barrier: 9 inputs, hidden 32,128,128,256,256,256,256,128,128,32, tanh.
inline nn::MlpSpec PandaSpec() {
  return {9, {32, 128, 128, 256, 256, 256, 256, 128, 128, 32}, 1, nn::Activation::kTanh};
}

/// "4-64-64-64-1 tanh": for benchmark labels.
inline std::string Describe(const nn::MlpSpec& spec) {
  std::string out;
  for (int w : spec.Widths()) out += (out.empty() ? "" : "-") + std::to_string(w);
  return out + (spec.activation == nn::Activation::kTanh ? " tanh" : " relu");
}

}  // namespace secure::bench
