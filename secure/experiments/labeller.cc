// The labeller capability's defaults (Domain::Label, Domain::SampleQueryPool; domain.h).
#include <algorithm>
#include <cmath>
#include <numeric>

#include "secure/common/error.h"
#include "secure/common/random_order.h"
#include "secure/common/rng.h"
#include "secure/experiments/domain.h"

namespace secure::experiments {

std::vector<int> Domain::Label(const Eigen::Ref<const Eigen::MatrixXf>&, std::uint64_t) const {
  SECURE_THROW("the " << name() << " domain has no labeller (a simulated person who labels "
                         "states; domains with one: those whose Domain::HasLabeller() is true)");
}

void CheckLabellerStates(const std::string& domain, const Eigen::Ref<const Eigen::MatrixXf>& states,
                         const std::vector<std::string>& features) {
  const long dim = static_cast<long>(features.size());
  SECURE_CHECK(states.rows() == dim, domain << " labeller: states have " << states.rows()
                                            << " features, expected " << dim
                                            << " (the observation: " << features.front()
                                            << ", ..., " << features.back() << ")");
  for (long i = 0; i < states.cols(); ++i)
    for (long r = 0; r < dim; ++r)
      SECURE_CHECK(std::isfinite(states(r, i)),
                   domain << " labeller: state " << i << ", feature "
                          << features[static_cast<std::size_t>(r)] << " = " << states(r, i)
                          << ": not finite (the person cannot judge it)");
}

data::StateSet Domain::SampleQueryPool(long count, std::uint64_t seed) const {
  SECURE_CHECK(count >= 1, "query pool: count = " << count << ", must be >= 1");
  const DomainData d = GenerateData(seed);
  const long n = d.safe.size() + d.near_dangerous.size();
  Rng rng(seed ^ 0x9001'0000'0000'0000ULL);
  std::vector<long> order = RandomPermutation(n, rng);
  order.resize(static_cast<std::size_t>(std::min(n, count)));
  data::StateSet pool;
  pool.source = "the " + name() + " query pool (data seed " + std::to_string(seed) + ")";
  pool.features = d.safe.features;
  pool.states.resize(d.safe.dim(), static_cast<long>(order.size()));
  for (std::size_t j = 0; j < order.size(); ++j) {
    const long i = order[j];
    pool.states.col(static_cast<long>(j)) =
        i < d.safe.size() ? d.safe.states.col(i) : d.near_dangerous.states.col(i - d.safe.size());
  }
  return pool;
}

}  // namespace secure::experiments
