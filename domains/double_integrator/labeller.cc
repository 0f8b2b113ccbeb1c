// DoubleIntegratorDomain's labeller (experiments::Domain::Label): the person is the ground truth.
#include <string>

#include "domains/double_integrator/domain.h"
#include "secure/common/error.h"
#include "secure/common/rng.h"

namespace secure::domains::double_integrator {

std::vector<int> DoubleIntegratorDomain::Label(const Eigen::Ref<const Eigen::MatrixXf>& states,
                                               std::uint64_t) const {
  SECURE_CHECK(states.rows() == kStateDim, "double-integrator labeller: states have "
                                               << states.rows() << " features, expected "
                                               << kStateDim << " (x, y, vx, vy)");
  options_.task.truth.Validate();
  Eigen::VectorXd h(states.cols());
  options_.task.truth.H(states, h);
  std::vector<int> labels(static_cast<std::size_t>(states.cols()));
  for (long i = 0; i < states.cols(); ++i) labels[static_cast<std::size_t>(i)] = h(i) >= 0 ? 1 : 0;
  return labels;
}

std::string DoubleIntegratorDomain::LabellerDescription() const {
  return "the ground truth h*(s) >= 0 (safe) of task.truth, without noise";
}

data::StateSet DoubleIntegratorDomain::SampleQueryPool(long count, std::uint64_t seed) const {
  SECURE_CHECK(count >= 1, "query pool: count = " << count << ", must be >= 1");
  const StateBox box;
  Rng rng(seed ^ 0x9001'd1d1'0000'0000ULL);
  data::StateSet pool;
  pool.source = "uniform states in the validation box (seed " + std::to_string(seed) + ")";
  pool.features = StateFeatures();
  pool.states.resize(kStateDim, count);
  for (long i = 0; i < count; ++i)
    for (int r = 0; r < kStateDim; ++r)
      pool.states(r, i) = static_cast<float>(
          rng.Uniform(box.lo[static_cast<std::size_t>(r)], box.hi[static_cast<std::size_t>(r)]));
  return pool;
}

}  // namespace secure::domains::double_integrator
