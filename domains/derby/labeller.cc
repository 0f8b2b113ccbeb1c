// DerbyDomain's labeller (experiments::Domain::Label): the person calls a state near-dangerous
// when the nearest observed car is within the near-dangerous generator's largest distance.
#include <algorithm>
#include <cmath>
#include <sstream>

#include "domains/derby/domain.h"
#include "secure/common/error.h"

namespace secure::domains::derby {

double DerbyDomain::LabelDistance() const {
  const std::vector<double>& rho = options_.near_dangerous.rho;
  return rho.empty() ? 0.0 : *std::max_element(rho.begin(), rho.end());
}

std::vector<int> DerbyDomain::Label(const Eigen::Ref<const Eigen::MatrixXf>& states,
                                    std::uint64_t) const {
  SECURE_CHECK(states.rows() == kObservationDim, "derby labeller: states have "
                                                     << states.rows() << " features, expected "
                                                     << kObservationDim << " (the observation)");
  const double limit = LabelDistance();
  std::vector<int> labels(static_cast<std::size_t>(states.cols()));
  for (long i = 0; i < states.cols(); ++i) {
    double nearest = 1e30;
    for (int c = 0; c < 12; ++c) {
      const double dx = states(4 + 4 * c, i), dy = states(5 + 4 * c, i);
      nearest = std::min(nearest, std::sqrt(dx * dx + dy * dy));
    }
    labels[static_cast<std::size_t>(i)] = nearest <= limit ? 0 : 1;
  }
  return labels;
}

std::string DerbyDomain::LabellerDescription() const {
  std::ostringstream s;
  s << "near-dangerous if the nearest observed car is within " << LabelDistance()
    << " (the near-dangerous generator's largest rho) of the ego, else safe; no noise";
  return s.str();
}

}  // namespace secure::domains::derby
