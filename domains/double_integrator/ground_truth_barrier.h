#pragma once
// The double integrator's analytic CBF (GroundTruth) as a cbf::Barrier, so that the shield, the
// grid validation and the CLI can use it wherever a learned barrier goes: h is computed in double
// precision and returned as float.
#include <Eigen/Core>
#include <functional>
#include <memory>
#include <string>

#include "domains/double_integrator/double_integrator.h"
#include "secure/cbf/barrier.h"
#include "secure/cbf/validation.h"

namespace secure::domains::double_integrator {

class GroundTruthBarrier final : public cbf::Barrier {
 public:
  explicit GroundTruthBarrier(const GroundTruth& truth);
  int state_dim() const override { return kStateDim; }
  std::string Describe() const override;

 protected:
  void DoEvaluate(const Eigen::Ref<const Eigen::MatrixXf>& states,
                  Eigen::Ref<Eigen::VectorXf> h) override;

 private:
  GroundTruth truth_;
};

/// The states of `grid` as a validation source (cbf::ValidateOnGrid); `grid` must outlive it.
cbf::StateSource GridStates(const Grid& grid);

/// Table 1's validation: `make_barrier` against the ground truth `truth` on `grid`.
cbf::Confusion ValidateAgainstGroundTruth(
    const std::function<std::unique_ptr<cbf::Barrier>()>& make_barrier, const GroundTruth& truth,
    const Grid& grid, const cbf::GridValidationOptions& options = {});

}  // namespace secure::domains::double_integrator
