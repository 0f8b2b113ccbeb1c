// Every registered domain's Environment::Step() and shield model allocate nothing
// (domains/environment.h, domains/dynamics.h): a counting C allocator (tests/malloc_counter.h;
// operator new and Eigen both allocate through malloc), so this is its own executable. Skipped
// under AddressSanitizer, which owns malloc (tests/sanitizers.h; CMake does not build it in a
// sanitizer build).

#include <gtest/gtest.h>

#include <memory>
#include <string>

#include "secure/common/rng.h"
#include "secure/experiments/domain.h"
#include "tests/domains/domain_contract_util.h"
#include "tests/malloc_counter.h"
#include "tests/sanitizers.h"

namespace secure::test {
namespace {

class DomainAlloc : public ::testing::TestWithParam<std::string> {};

TEST_P(DomainAlloc, StepShieldModelAndBackupDoNotAllocate) {
  if (SECURE_TEST_ASAN) GTEST_SKIP() << "counts calls of a replaced malloc: not under ASan";
  std::unique_ptr<experiments::Domain> domain =
      experiments::DomainRegistry::Global().Make(GetParam(), experiments::Profile::kQuick);
  std::unique_ptr<domains::Environment> env = domain->MakeEnvironment();
  const int steps = std::min(env->max_steps(), 50);
  Eigen::VectorXf o(env->observation_dim()), a(env->action_dim()), backup(env->action_dim());
  Eigen::MatrixXf actions = Eigen::MatrixXf::Zero(env->action_dim(), 64);
  Eigen::MatrixXf next(env->ShieldModel().state_dim(), 64);
  Rng rng(1), action_rng(2);
  for (Eigen::Index j = 0; j < actions.cols(); ++j) DrawAction(action_rng, actions.col(j));
  env->Reset(rng, o);
  BeginCountingMalloc();
  for (int t = 0; t < steps; ++t) {
    DrawAction(action_rng, a);
    env->ShieldModel().Step(o, actions, next);
    env->BackupAction(o, backup);
    env->Step(a, o);
  }
  const long calls = EndCountingMalloc();
  EXPECT_EQ(calls, 0) << GetParam();
}

INSTANTIATE_TEST_SUITE_P(AllRegistered, DomainAlloc, ::testing::ValuesIn(ContractDomainNames()),
                         [](const ::testing::TestParamInfo<std::string>& info) {
                           return ParamName(info.param);
                         });

}  // namespace
}  // namespace secure::test
