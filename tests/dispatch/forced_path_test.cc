// The forced dispatch paths (tests/dispatch/README.md): SECURE_MATMUL_BACKEND replaces kAuto and
// LIBXSMM_TARGET picks LIBXSMM's instruction set. Under `ctest -L dispatch` each run states the
// path it expects in SECURE_DISPATCH_EXPECT ("eigen", or "libxsmm:<target>"), and this test fails
// if the process did not take that path, so a forced run cannot silently test the default.
#include <gtest/gtest.h>

#include <cstdlib>
#include <optional>
#include <string>

#include "secure/common/error.h"
#include "secure/common/rng.h"
#include "secure/nn/inference_mlp.h"
#include "secure/nn/mlp.h"
#include "tests/nn/nn_test_util.h"
#include "tests/test_util.h"

namespace secure::nn {
namespace {

// Sets an environment variable for one scope and restores its previous value.
class ScopedEnv {
 public:
  ScopedEnv(const char* name, const char* value) : name_(name) {
    if (const char* old = std::getenv(name)) old_ = old;
    setenv(name, value, 1);
  }
  ~ScopedEnv() {
    if (old_) {
      setenv(name_, old_->c_str(), 1);
    } else {
      unsetenv(name_);
    }
  }

 private:
  const char* name_;
  std::optional<std::string> old_;
};

MlpParams SmallParams() {
  MlpParams params;
  params.spec = test::Spec(4, {64, 64}, 1, Activation::kTanh);
  int in = params.spec.input_dim;
  for (int width : {64, 64, 1}) {
    DenseLayer layer;
    layer.weight = Eigen::MatrixXf::Random(width, in) * 0.3f;
    layer.bias = Eigen::VectorXf::Random(width) * 0.1f;
    params.layers.push_back(layer);
    in = width;
  }
  return params;
}

TEST(ForcedPath, TheProcessTakesTheExpectedPath) {
  const char* expect = std::getenv("SECURE_DISPATCH_EXPECT");
  if (expect == nullptr) GTEST_SKIP() << "not a forced run (SECURE_DISPATCH_EXPECT unset)";
  const std::string expected = expect;
  const InferenceMlp mlp(SmallParams(), Normalizer::Identity(4));
  if (expected == "eigen") {
    EXPECT_EQ(InferenceMlp::ForcedBackend(), MatmulBackend::kEigen);
    EXPECT_EQ(mlp.backend(), MatmulBackend::kEigen);
    return;
  }
  const std::string prefix = "libxsmm:";
  ASSERT_EQ(expected.rfind(prefix, 0), 0u) << "SECURE_DISPATCH_EXPECT = '" << expected << "'";
  EXPECT_EQ(mlp.backend(), MatmulBackend::kLibxsmm);
  EXPECT_EQ(std::string(InferenceMlp::LibxsmmTarget()), expected.substr(prefix.size()));
}

TEST(ForcedPath, TheVariableReplacesOnlyAuto) {
  const MlpParams params = SmallParams();
  {
    ScopedEnv env("SECURE_MATMUL_BACKEND", "eigen");
    EXPECT_EQ(InferenceMlp::ForcedBackend(), MatmulBackend::kEigen);
    EXPECT_EQ(InferenceMlp(params, Normalizer::Identity(4)).backend(), MatmulBackend::kEigen);
    // An explicit request is kept.
    const InferenceMlp explicit_libxsmm(params, Normalizer::Identity(4), MatmulBackend::kLibxsmm);
    EXPECT_EQ(explicit_libxsmm.backend(), MatmulBackend::kLibxsmm);
  }
  {
    ScopedEnv env("SECURE_MATMUL_BACKEND", "");
    EXPECT_EQ(InferenceMlp::ForcedBackend(), MatmulBackend::kAuto);
  }
  {
    ScopedEnv env("SECURE_MATMUL_BACKEND", "auto");
    EXPECT_EQ(InferenceMlp::ForcedBackend(), MatmulBackend::kAuto);
  }
}

TEST(ForcedPath, AnUnknownValueIsAnErrorNamingTheVariable) {
  ScopedEnv env("SECURE_MATMUL_BACKEND", "avx9000");
  const std::string message =
      secure::test::ErrorOf([] { InferenceMlp(SmallParams(), Normalizer::Identity(4)); });
  EXPECT_HAS(message, "SECURE_MATMUL_BACKEND");
  EXPECT_HAS(message, "'avx9000'");
  EXPECT_HAS(message, "must be one of auto, libxsmm, eigen");
}

}  // namespace
}  // namespace secure::nn
