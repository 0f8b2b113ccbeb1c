#include "secure/cbf/barrier.h"

#include <algorithm>
#include <cmath>
#include <sstream>

#include "secure/common/error.h"
#include "secure/common/strings.h"

namespace secure::cbf {

void Barrier::CheckShapes(const Eigen::Ref<const Eigen::MatrixXf>& states,
                          const Eigen::Ref<Eigen::VectorXf>& h) const {
  SECURE_CHECK(states.rows() == state_dim(), Describe() << ": states have " << states.rows()
                                                        << " rows, expected " << state_dim());
  SECURE_CHECK(h.size() == states.cols(), Describe()
                                              << ": output has " << h.size() << " entries for "
                                              << states.cols() << " states");
}

void Barrier::Evaluate(const Eigen::Ref<const Eigen::MatrixXf>& states,
                       Eigen::Ref<Eigen::VectorXf> h) {
  CheckShapes(states, h);
  DoEvaluate(states, h);
}

void Barrier::EvaluateDense(const Eigen::Ref<const Eigen::MatrixXf>& states,
                            Eigen::Ref<Eigen::VectorXf> h) {
  CheckShapes(states, h);
  DoEvaluateDense(states, h);
}

void Barrier::EvaluateGradient(const Eigen::Ref<const Eigen::MatrixXf>& states,
                               Eigen::Ref<Eigen::VectorXf> h,
                               Eigen::Ref<Eigen::MatrixXf> gradients) {
  CheckShapes(states, h);
  SECURE_CHECK(gradients.rows() == state_dim() && gradients.cols() == states.cols(),
               Describe() << ": gradients are " << gradients.rows() << " x " << gradients.cols()
                          << ", expected " << state_dim() << " x " << states.cols());
  DoEvaluateGradient(states, h, gradients);
}

void Barrier::DoEvaluateGradient(const Eigen::Ref<const Eigen::MatrixXf>& states,
                                 Eigen::Ref<Eigen::VectorXf> h,
                                 Eigen::Ref<Eigen::MatrixXf> gradients) {
  // Central differences, one state at a time: the state and its 2 d neighbours in one batch.
  const int d = state_dim();
  if (fd_states_.rows() != d) {
    fd_states_.resize(d, 2 * d + 1);
    fd_h_.resize(2 * d + 1);
  }
  for (Eigen::Index i = 0; i < states.cols(); ++i) {
    fd_states_.colwise() = states.col(i);
    for (int r = 0; r < d; ++r) {
      const float step = 1e-3f * std::max(1.0f, std::abs(states(r, i)));
      fd_states_(r, 1 + 2 * r) += step;
      fd_states_(r, 2 + 2 * r) -= step;
    }
    DoEvaluate(fd_states_, fd_h_);
    h[i] = fd_h_[0];
    for (int r = 0; r < d; ++r) {
      // The steps as represented (s + step and s - step rounded to float).
      const float width = fd_states_(r, 1 + 2 * r) - fd_states_(r, 2 + 2 * r);
      gradients(r, i) = (fd_h_[1 + 2 * r] - fd_h_[2 + 2 * r]) / width;
    }
  }
}

std::vector<int> FeatureRows(const std::vector<std::string>& wanted,
                             const std::vector<std::string>& available, const std::string& source,
                             const std::string& reader) {
  std::vector<int> rows;
  rows.reserve(wanted.size());
  for (const std::string& name : wanted) {
    const auto it = std::find(available.begin(), available.end(), name);
    SECURE_CHECK(it != available.end(),
                 source << " has " << available.size() << " features (" << Join(available)
                        << "), without '" << name << "', which " << reader << " reads ("
                        << wanted.size() << ": " << Join(wanted) << ")");
    rows.push_back(static_cast<int>(it - available.begin()));
  }
  return rows;
}

SelectRows::SelectRows(std::unique_ptr<Barrier> inner, int state_dim, std::vector<int> rows,
                       int chunk)
    : inner_(std::move(inner)), state_dim_(state_dim), rows_(std::move(rows)) {
  SECURE_CHECK(inner_ != nullptr, "SelectRows: no inner barrier");
  SECURE_CHECK(static_cast<int>(rows_.size()) == inner_->state_dim(),
               "SelectRows: " << rows_.size() << " rows for " << inner_->Describe()
                              << ", which reads " << inner_->state_dim());
  SECURE_CHECK(chunk > 0, "SelectRows: chunk = " << chunk << ", must be > 0");
  for (std::size_t k = 0; k < rows_.size(); ++k)
    SECURE_CHECK(rows_[k] >= 0 && rows_[k] < state_dim_,
                 "SelectRows: rows[" << k << "] = " << rows_[k] << ", must be in [0, "
                                     << state_dim_ << ")");
  buffer_.resize(static_cast<Eigen::Index>(rows_.size()), chunk);
}

std::string SelectRows::Describe() const {
  std::ostringstream s;
  s << inner_->Describe() << " on " << rows_.size() << " of " << state_dim_ << " state rows";
  return s.str();
}

void SelectRows::DoEvaluateGradient(const Eigen::Ref<const Eigen::MatrixXf>& states,
                                    Eigen::Ref<Eigen::VectorXf> h,
                                    Eigen::Ref<Eigen::MatrixXf> gradients) {
  const Eigen::Index n = states.cols();
  const Eigen::Index chunk = buffer_.cols();
  const Eigen::Index d = static_cast<Eigen::Index>(rows_.size());
  if (gradient_buffer_.cols() != chunk) gradient_buffer_.resize(d, chunk);
  gradients.setZero();
  for (Eigen::Index first = 0; first < n; first += chunk) {
    const Eigen::Index m = std::min(chunk, n - first);
    for (Eigen::Index j = 0; j < m; ++j)
      for (Eigen::Index k = 0; k < d; ++k)
        buffer_(k, j) = states(rows_[static_cast<std::size_t>(k)], first + j);
    inner_->EvaluateGradient(buffer_.leftCols(m), h.segment(first, m),
                             gradient_buffer_.leftCols(m));
    // A row selected twice reads the same state row: its gradients add up.
    for (Eigen::Index j = 0; j < m; ++j)
      for (Eigen::Index k = 0; k < d; ++k)
        gradients(rows_[static_cast<std::size_t>(k)], first + j) += gradient_buffer_(k, j);
  }
}

void SelectRows::DoEvaluateStates(const Eigen::Ref<const Eigen::MatrixXf>& states,
                                  Eigen::Ref<Eigen::VectorXf> h, bool dense) {
  const Eigen::Index n = states.cols();
  const Eigen::Index chunk = buffer_.cols();
  const Eigen::Index d = static_cast<Eigen::Index>(rows_.size());
  for (Eigen::Index first = 0; first < n; first += chunk) {
    const Eigen::Index m = std::min(chunk, n - first);
    for (Eigen::Index j = 0; j < m; ++j)
      for (Eigen::Index k = 0; k < d; ++k)
        buffer_(k, j) = states(rows_[static_cast<std::size_t>(k)], first + j);
    if (dense) {
      inner_->EvaluateDense(buffer_.leftCols(m), h.segment(first, m));
    } else {
      inner_->Evaluate(buffer_.leftCols(m), h.segment(first, m));
    }
  }
}

}  // namespace secure::cbf
