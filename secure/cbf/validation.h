#pragma once
// How good is a barrier? Accuracy on labelled states, and the paper's Table 1 confusion matrix
// against a ground truth on a grid.

#include <Eigen/Core>
#include <functional>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>

#include "secure/cbf/barrier.h"

namespace secure::cbf {

struct ClassAccuracy {
  double safe = 0.0;            // fraction of safe states with h >= 0
  double near_dangerous = 0.0;  // fraction of near-dangerous states with h < 0
  double Balanced() const { return 0.5 * (safe + near_dangerous); }
};

/// Accuracy of any barrier on labelled states (each (dim x N)); a class with no states scores 0.
ClassAccuracy EvaluateAccuracy(Barrier& barrier, const Eigen::Ref<const Eigen::MatrixXf>& safe,
                               const Eigen::Ref<const Eigen::MatrixXf>& near_dangerous);

/// The paper's Table 1: counts of (predicted, true) labels over a grid, where "safe" is h >= 0
/// for both the learned barrier and the ground truth.
struct Confusion {
  long safe_as_safe = 0;      // predicted safe | truly safe
  long safe_as_unsafe = 0;    // predicted unsafe | truly safe   (over-conservative)
  long unsafe_as_safe = 0;    // predicted safe | truly unsafe   (under-conservative)
  long unsafe_as_unsafe = 0;  // predicted unsafe | truly unsafe

  long truly_safe() const { return safe_as_safe + safe_as_unsafe; }
  long truly_unsafe() const { return unsafe_as_safe + unsafe_as_unsafe; }
  long total() const { return truly_safe() + truly_unsafe(); }
  /// Rates as fractions of the true class (0 if the class is empty).
  double SafeCorrect() const;        // P(pred safe | safe)
  double OverConservative() const;   // P(pred unsafe | safe)
  double UnderConservative() const;  // P(pred safe | unsafe)
  double UnsafeCorrect() const;      // P(pred unsafe | unsafe)
  Confusion& operator+=(const Confusion& other);
  nlohmann::json ToJson() const;
};

struct GridValidationOptions {
  int threads = 2;    // worker threads; each gets its own barrier evaluator
  long chunk = 4096;  // states per batch
};

/// Confusion of the barriers made by `make_barrier` (called once per worker thread, each
/// evaluator is used by one thread only) against the double integrator's ground truth on `grid`.
/// Deterministic: the counts do not depend on threads or chunk.
/// The states of a validation grid, produced in chunks: `size` states of `state_dim` rows;
/// fill(first, n, out) writes states [first, first + n) into out (state_dim x n). `fill` is called
/// from several threads at once.
struct StateSource {
  int state_dim = 0;
  long size = 0;
  std::function<void(long first, long n, Eigen::Ref<Eigen::MatrixXf> out)> fill;
};

/// The confusion matrix of a barrier against a reference barrier (a domain's ground truth) on
/// every state of `states`: a state is truly safe when the reference's h >= 0, predicted safe when
/// the barrier's h >= 0. Each worker thread makes its own evaluators (the factories are called
/// on the calling thread). @throws secure::Error on dimension mismatches or bad options.
Confusion ValidateOnGrid(const std::function<std::unique_ptr<Barrier>()>& make_barrier,
                         const std::function<std::unique_ptr<Barrier>()>& make_reference,
                         const StateSource& states, const GridValidationOptions& options = {});

}  // namespace secure::cbf
