#include "secure/cbf/min_barrier.h"

#include <algorithm>
#include <sstream>

#include "secure/common/error.h"

namespace secure::cbf {
namespace {

// f(first, m) for the chunks [first, first + m) of n states, m <= chunk.
template <typename F>
void ForEachChunk(Eigen::Index n, Eigen::Index chunk, F&& f) {
  for (Eigen::Index first = 0; first < n; first += chunk) f(first, std::min(chunk, n - first));
}

}  // namespace

MinBarrier::MinBarrier(std::vector<std::unique_ptr<Barrier>> members, int chunk)
    : members_(std::move(members)) {
  SECURE_CHECK(!members_.empty(), "MinBarrier: no member barriers");
  SECURE_CHECK(chunk > 0, "MinBarrier: chunk = " << chunk << ", must be > 0");
  for (std::size_t k = 0; k < members_.size(); ++k)
    SECURE_CHECK(members_[k] != nullptr, "MinBarrier: member " << k << " is null");
  state_dim_ = members_[0]->state_dim();
  bool same_description = true;
  for (std::size_t k = 0; k < members_.size(); ++k) {
    SECURE_CHECK(members_[k]->state_dim() == state_dim_,
                 "MinBarrier: member " << k << " (" << members_[k]->Describe() << ") reads "
                                       << members_[k]->state_dim() << " state rows, member 0 "
                                       << state_dim_);
    analytic_ = analytic_ && members_[k]->analytic_gradient();
    same_description = same_description && members_[k]->Describe() == members_[0]->Describe();
  }
  std::ostringstream d;
  d << "min of " << members_.size() << " ";
  if (same_description) {
    d << members_[0]->Describe();
  } else {
    d << "barriers (";
    for (std::size_t k = 0; k < members_.size(); ++k)
      d << (k ? "; " : "") << members_[k]->Describe();
    d << ")";
  }
  description_ = d.str();
  scratch_h_.resize(chunk);
  if (analytic_) scratch_gradients_.resize(state_dim_, chunk);
}

void MinBarrier::DoEvaluateStates(const Eigen::Ref<const Eigen::MatrixXf>& states,
                                  Eigen::Ref<Eigen::VectorXf> h, bool dense) {
  ForEachChunk(states.cols(), scratch_h_.size(), [&](Eigen::Index first, Eigen::Index m) {
    const auto block = states.middleCols(first, m);
    auto out = h.segment(first, m);
    auto scratch = scratch_h_.head(m);
    for (std::size_t k = 0; k < members_.size(); ++k) {
      Barrier& member = *members_[k];
      if (k == 0) {
        dense ? member.EvaluateDense(block, out) : member.Evaluate(block, out);
        continue;
      }
      dense ? member.EvaluateDense(block, scratch) : member.Evaluate(block, scratch);
      out = out.cwiseMin(scratch);
    }
  });
}

void MinBarrier::DoEvaluateGradient(const Eigen::Ref<const Eigen::MatrixXf>& states,
                                    Eigen::Ref<Eigen::VectorXf> h,
                                    Eigen::Ref<Eigen::MatrixXf> gradients) {
  if (!analytic_) {
    Barrier::DoEvaluateGradient(states, h, gradients);  // central differences of the minimum
    return;
  }
  ForEachChunk(states.cols(), scratch_h_.size(), [&](Eigen::Index first, Eigen::Index m) {
    const auto block = states.middleCols(first, m);
    auto out_h = h.segment(first, m);
    auto out_g = gradients.middleCols(first, m);
    members_[0]->EvaluateGradient(block, out_h, out_g);
    for (std::size_t k = 1; k < members_.size(); ++k) {
      members_[k]->EvaluateGradient(block, scratch_h_.head(m), scratch_gradients_.leftCols(m));
      // Strictly less: on ties the earlier member keeps the state (first of least h).
      for (Eigen::Index j = 0; j < m; ++j) {
        if (scratch_h_[j] < out_h[j]) {
          out_h[j] = scratch_h_[j];
          out_g.col(j) = scratch_gradients_.col(j);
        }
      }
    }
  });
}

}  // namespace secure::cbf
