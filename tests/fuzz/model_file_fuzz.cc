// libFuzzer target: model files (nn/model_file.h) and the loaders built on them (barrier MLP,
// per-car barrier, Gaussian policy). Inputs whose first byte is odd get a correct CRC trailer
// appended after the rest, so that mutations reach the header and payload checks behind the
// checksum; the others are read as they are. Any input must load or throw secure::Error; a
// model that loads must evaluate without a sanitizer finding.
#include <boost/crc.hpp>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <string>

#include "secure/cbf/barrier_net.h"
#include "secure/cbf/car_barrier.h"
#include "secure/common/error.h"
#include "secure/nn/model_file.h"
#include "secure/policy/gaussian_policy.h"
#include "tests/fuzz/fuzz_util.h"

namespace {

// The writer's trailer (model_file.cc): CRC-32 of everything after the format line.
std::string WithValidTrailer(const std::string& body) {
  const std::size_t first_newline = body.find('\n');
  const std::size_t start = first_newline == std::string::npos ? body.size() : first_newline + 1;
  boost::crc_32_type crc;
  crc.process_bytes(body.data() + start, body.size() - start);
  char hex[9];
  std::snprintf(hex, sizeof hex, "%08x", static_cast<unsigned>(crc.checksum()));
  return body + "\ncrc32 " + hex + "\n";
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace secure;
  if (size == 0) return 0;
  std::string bytes(reinterpret_cast<const char*>(data) + 1, size - 1);
  if (data[0] & 1) bytes = WithValidTrailer(bytes);
  try {
    nn::ParseModelFile(bytes, "fuzz");
  } catch (const Error&) {
    return 0;  // the loaders below would fail the same way
  }
  const std::string& path = fuzz::WriteScratch(bytes, ".model");
  try {
    const cbf::BarrierNet net = cbf::BarrierNet::Load(path);
    auto barrier = net.MakeEvaluator(8);
    Eigen::MatrixXf states = Eigen::MatrixXf::Zero(net.state_dim(), 3);
    Eigen::VectorXf h(3);
    barrier->Evaluate(states, h);
  } catch (const Error&) {
  }
  try {
    const cbf::CarBarrierNet net = cbf::CarBarrierNet::Load(path);
    auto barrier = net.MakeEvaluator(4);
    Eigen::MatrixXf states = Eigen::MatrixXf::Zero(barrier->state_dim(), 2);
    Eigen::VectorXf h(2);
    barrier->Evaluate(states, h);
  } catch (const Error&) {
  }
  try {
    const policy::GaussianPolicy pi = policy::GaussianPolicy::Load(path);
    policy::PolicyEvaluator evaluator(pi);
    Eigen::VectorXf obs = Eigen::VectorXf::Zero(pi.observation_dim());
    Eigen::VectorXf mu(pi.action_dim());
    evaluator.Mean(obs, mu);
  } catch (const Error&) {
  }
  return 0;
}
