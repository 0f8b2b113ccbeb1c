#include "secure/cbf/barrier.h"

#include <algorithm>
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

void SelectRows::DoEvaluate(const Eigen::Ref<const Eigen::MatrixXf>& states,
                            Eigen::Ref<Eigen::VectorXf> h) {
  Gathered(states, h, /*dense=*/false);
}

void SelectRows::DoEvaluateDense(const Eigen::Ref<const Eigen::MatrixXf>& states,
                                 Eigen::Ref<Eigen::VectorXf> h) {
  Gathered(states, h, /*dense=*/true);
}

void SelectRows::Gathered(const Eigen::Ref<const Eigen::MatrixXf>& states,
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
