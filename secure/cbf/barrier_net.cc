#include "secure/cbf/barrier_net.h"

#include <algorithm>
#include <sstream>

#include "secure/cbf/min_barrier.h"
#include "secure/common/error.h"
#include "secure/common/strings.h"
#include "secure/nn/model_file.h"

namespace secure::cbf {
namespace {

std::string DescribeSpec(const nn::MlpSpec& spec) {
  std::ostringstream t;
  t << "barrier_mlp ";
  const auto widths = spec.Widths();
  for (std::size_t i = 0; i < widths.size(); ++i) t << (i ? "-" : "") << widths[i];
  t << " " << ToString(nn::kActivationNames, spec.activation);
  return t.str();
}

// One member's MLP and normaliser, for a network input of `inputs` (the features).
void ValidateMember(const nn::MlpParams& mlp, const nn::Normalizer& normalizer, int inputs,
                    const std::string& what) {
  mlp.Validate(what);
  SECURE_CHECK(mlp.spec.output_dim == 1,
               what << ": barrier network has " << mlp.spec.output_dim << " outputs, expected 1");
  normalizer.Validate(what + " normalizer");
  SECURE_CHECK(normalizer.dim() == mlp.spec.input_dim,
               what << ": normalizer has dimension " << normalizer.dim() << ", network input is "
                    << mlp.spec.input_dim);
  SECURE_CHECK(mlp.spec.input_dim == inputs,
               what << ": network input is " << mlp.spec.input_dim << ", member 0's is "
                    << inputs);
}

// The names of member k's MLP and normaliser in a model file.
std::string MlpName(int k) { return k == 0 ? "barrier" : "barrier" + std::to_string(k); }
std::string NormalizerName(int k) { return k == 0 ? "input" : "input" + std::to_string(k); }

}  // namespace

BarrierMember BarrierNet::Member(int k) const {
  SECURE_CHECK(k >= 0 && k < members(),
               "BarrierNet::Member(" << k << "): the barrier has " << members() << " members");
  if (k == 0) return {mlp, normalizer};
  return more_members[static_cast<std::size_t>(k - 1)];
}

void BarrierNet::Validate(const std::string& what) const {
  ValidateMember(mlp, normalizer, mlp.spec.input_dim, what);
  SECURE_CHECK(static_cast<int>(features.size()) == mlp.spec.input_dim,
               what << ": " << features.size() << " feature names for a network input of "
                    << mlp.spec.input_dim);
  SECURE_CHECK(members() <= kMaxBarrierEnsemble,
               what << ": " << members() << " members, at most " << kMaxBarrierEnsemble);
  for (std::size_t k = 0; k < more_members.size(); ++k)
    ValidateMember(more_members[k].mlp, more_members[k].normalizer, mlp.spec.input_dim,
                   what + " member " + std::to_string(k + 1));
}

void BarrierNet::CheckFeatures(const std::vector<std::string>& data_features,
                               const std::string& source, const std::string& model_name) const {
  if (data_features == features) return;
  SECURE_THROW(source << " has " << data_features.size() << " features (" << Join(data_features)
                      << "); " << model_name << " expects " << features.size() << " ("
                      << Join(features) << ")");
}

void BarrierNet::Save(const std::string& path) const {
  Validate(path);
  nn::ModelFile file;
  file.kind = more_members.empty() ? kBarrierModelKind : kBarrierEnsembleModelKind;
  file.metadata["features"] = features;
  if (!more_members.empty()) file.metadata["members"] = members();
  file.metadata["provenance"] = provenance;
  for (int k = 0; k < members(); ++k) {
    const BarrierMember m = Member(k);
    nn::AddMlp(MlpName(k), m.mlp, &file);
    nn::AddNormalizer(NormalizerName(k), m.normalizer, &file);
  }
  nn::WriteModelFile(path, file);
}

BarrierNet BarrierNet::Load(const std::string& path) {
  const nn::ModelFile file = nn::ReadModelFile(path);
  const bool ensemble = file.kind == kBarrierEnsembleModelKind;
  SECURE_CHECK(file.kind == kBarrierModelKind || ensemble,
               path << ": holds a '" << file.kind << "' model, expected '" << kBarrierModelKind
                    << "' or '" << kBarrierEnsembleModelKind << "'");
  BarrierNet net;
  SECURE_CHECK(file.metadata.contains("features") && file.metadata["features"].is_array(),
               path << ": metadata field 'features' is missing or not a list");
  for (const auto& f : file.metadata["features"]) {
    SECURE_CHECK(f.is_string(), path << ": metadata field 'features' holds a non-string");
    net.features.push_back(f.get<std::string>());
  }
  int members = 1;
  if (ensemble) {
    const auto it = file.metadata.find("members");
    SECURE_CHECK(it != file.metadata.end() && it->is_number_integer(),
                 path << ": metadata field 'members' is missing or not an integer");
    const long long k = it->get<long long>();
    SECURE_CHECK(k >= 2 && k <= kMaxBarrierEnsemble,
                 path << ": metadata field 'members' = " << k << ", must be in [2, "
                      << kMaxBarrierEnsemble << "]");
    members = static_cast<int>(k);
  }
  if (file.metadata.contains("provenance")) net.provenance = file.metadata["provenance"];
  net.mlp = nn::GetMlp(MlpName(0), file, path);
  net.normalizer = nn::GetNormalizer(NormalizerName(0), file, path);
  for (int k = 1; k < members; ++k)
    net.more_members.push_back(
        {nn::GetMlp(MlpName(k), file, path), nn::GetNormalizer(NormalizerName(k), file, path)});
  // An ensemble's tensors are all its members': more would be members no reader uses.
  std::size_t expected = 0;
  for (int k = 0; k < members; ++k) expected += 2 * net.Member(k).mlp.layers.size() + 2;
  SECURE_CHECK(!ensemble || file.tensors.size() == expected,
               path << ": holds " << file.tensors.size() << " tensors, but its " << members
                    << " member(s) have " << expected << " (metadata field 'members' = "
                    << members << ")");
  net.Validate(path);
  return net;
}

std::unique_ptr<Barrier> BarrierNet::MakeEvaluator(int chunk) const {
  if (more_members.empty()) return std::make_unique<BarrierNetEvaluator>(*this, chunk);
  Validate();
  std::vector<std::unique_ptr<Barrier>> evaluators;
  evaluators.push_back(std::make_unique<BarrierNetEvaluator>(Member(0), chunk));
  for (const BarrierMember& m : more_members)
    evaluators.push_back(std::make_unique<BarrierNetEvaluator>(m, chunk));
  return std::make_unique<MinBarrier>(std::move(evaluators), chunk);
}

std::unique_ptr<Barrier> BarrierNet::MakeEvaluatorFor(
    const std::vector<std::string>& state_features, const std::string& source,
    const std::string& model_name, int chunk) const {
  if (state_features == features) return MakeEvaluator(chunk);
  std::vector<int> rows = FeatureRows(features, state_features, source, model_name);
  return std::make_unique<SelectRows>(MakeEvaluator(chunk),
                                      static_cast<int>(state_features.size()), std::move(rows),
                                      chunk);
}

BarrierNetEvaluator::BarrierNetEvaluator(const BarrierNet& net, int chunk)
    : BarrierNetEvaluator(BarrierMember{net.mlp, net.normalizer}, chunk) {
  net.Validate();
}

BarrierNetEvaluator::BarrierNetEvaluator(const BarrierMember& member, int chunk)
    : mlp_(member.mlp, member.normalizer),
      workspace_(mlp_.MakeWorkspace(chunk)),
      gradient_workspace_(mlp_.MakeGradientWorkspace(std::min(chunk, kGradientChunk))),
      description_(DescribeSpec(member.mlp.spec)) {
  ValidateMember(member.mlp, member.normalizer, member.mlp.spec.input_dim, "barrier");
}

void BarrierNetEvaluator::DoEvaluate(const Eigen::Ref<const Eigen::MatrixXf>& states,
                                     Eigen::Ref<Eigen::VectorXf> h) {
  const Eigen::Index n = states.cols();
  const Eigen::Index chunk = workspace_.max_batch();
  for (Eigen::Index first = 0; first < n; first += chunk) {
    const Eigen::Index m = std::min(chunk, n - first);
    // h is a column vector; the MLP writes a (1 x m) row: map the same memory as a row.
    Eigen::Map<Eigen::RowVectorXf> row(h.data() + first, m);
    mlp_.Forward(states.middleCols(first, m), workspace_, row);
  }
}

void BarrierNetEvaluator::DoEvaluateGradient(const Eigen::Ref<const Eigen::MatrixXf>& states,
                                             Eigen::Ref<Eigen::VectorXf> h,
                                             Eigen::Ref<Eigen::MatrixXf> gradients) {
  const Eigen::Index n = states.cols();
  const Eigen::Index chunk = gradient_workspace_.max_batch();
  for (Eigen::Index first = 0; first < n; first += chunk) {
    const Eigen::Index m = std::min(chunk, n - first);
    mlp_.ForwardGradient(states.middleCols(first, m), gradient_workspace_, h.segment(first, m),
                         gradients.middleCols(first, m));
  }
}

}  // namespace secure::cbf
