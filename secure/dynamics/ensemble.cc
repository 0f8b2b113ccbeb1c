#include "secure/dynamics/ensemble.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <set>
#include <sstream>
#include <utility>

#include "secure/common/error.h"
#include "secure/nn/model_file.h"

namespace secure::dynamics {
namespace {

std::vector<std::string> ReadNames(const nlohmann::json& metadata, const char* key,
                                   const std::string& path) {
  SECURE_CHECK(metadata.contains(key) && metadata[key].is_array(),
               path << ": metadata field '" << key << "' is missing or not a list");
  std::vector<std::string> names;
  for (const auto& f : metadata[key]) {
    SECURE_CHECK(f.is_string(), path << ": metadata field '" << key << "' holds a non-string");
    names.push_back(f.get<std::string>());
  }
  return names;
}

std::string MemberPrefix(int k) { return "member" + std::to_string(k); }

}  // namespace

void PessimismOptions::Validate() const {
  SECURE_CHECK(std::isfinite(kappa) && kappa >= 0,
               "pessimism: kappa = " << kappa << ", must be finite and >= 0");
  SECURE_CHECK(hold >= 1 && hold <= kMaxHold,
               "pessimism: hold = " << hold << ", must be in [1, " << kMaxHold << "]");
}

std::string PessimismOptions::Describe() const {
  std::ostringstream out;
  if (linear) out << "linear ";
  if (aggregate == Aggregate::kMin)
    out << "min";
  else
    out << "mean-" << kappa << "std";
  if (hold > 1) out << ", hold " << hold;
  return out.str();
}

PessimismOptions::Aggregate PessimismOptions::ParseAggregate(const std::string& text,
                                                             const std::string& what) {
  if (text == "min") return Aggregate::kMin;
  if (text == "mean-std") return Aggregate::kMeanStd;
  SECURE_THROW(what << " = '" << text << "', must be min | mean-std");
  return Aggregate::kMin;  // not reached
}

void EnsembleDynamics::Validate(const std::string& what) const {
  SECURE_CHECK(!state_features.empty(), what << ": no state features");
  SECURE_CHECK(!action_features.empty(), what << ": no action features");
  std::set<std::string> seen;
  for (const auto& names : {state_features, action_features})
    for (const std::string& f : names)
      SECURE_CHECK(seen.insert(f).second, what << ": feature '" << f << "' appears twice");
  SECURE_CHECK(num_members() >= 1 && num_members() <= kMaxMembers,
               what << ": " << num_members() << " members, must be in [1, " << kMaxMembers << "]");
  const int in = state_dim() + action_dim();
  input.Validate(what + " input normalizer");
  delta.Validate(what + " delta normalizer");
  SECURE_CHECK(input.dim() == in, what << ": input normalizer has " << input.dim()
                                       << " features, the model reads " << in);
  SECURE_CHECK(delta.dim() == state_dim(), what << ": delta normalizer has " << delta.dim()
                                                << " features, the state has " << state_dim());
  for (int k = 0; k < num_members(); ++k) {
    const nn::MlpParams& m = members[static_cast<std::size_t>(k)];
    m.Validate(what + " member " + std::to_string(k));
    SECURE_CHECK(m.spec.input_dim == in && m.spec.output_dim == state_dim(),
                 what << ": member " << k << " maps " << m.spec.input_dim << " -> "
                      << m.spec.output_dim << ", must map " << in << " -> " << state_dim());
  }
}

void EnsembleDynamics::Save(const std::string& path) const {
  Validate(path);
  nn::ModelFile file;
  file.kind = kEnsembleModelKind;
  file.metadata["state_features"] = state_features;
  file.metadata["action_features"] = action_features;
  file.metadata["members"] = num_members();
  file.metadata["provenance"] = provenance;
  nn::AddNormalizer("input", input, &file);
  nn::AddNormalizer("delta", delta, &file);
  for (int k = 0; k < num_members(); ++k)
    nn::AddMlp(MemberPrefix(k), members[static_cast<std::size_t>(k)], &file);
  nn::WriteModelFile(path, file);
}

EnsembleDynamics EnsembleDynamics::Load(const std::string& path) {
  const nn::ModelFile file = nn::ReadModelFile(path);
  SECURE_CHECK(file.kind == kEnsembleModelKind,
               path << ": a '" << file.kind << "' model, not a learned dynamics model ('"
                    << kEnsembleModelKind << "', from `secure dynamics train`)");
  EnsembleDynamics d;
  d.state_features = ReadNames(file.metadata, "state_features", path);
  d.action_features = ReadNames(file.metadata, "action_features", path);
  SECURE_CHECK(file.metadata.contains("members") && file.metadata["members"].is_number_integer(),
               path << ": metadata field 'members' is missing or not an integer");
  const long k = file.metadata["members"].get<long>();
  SECURE_CHECK(k >= 1 && k <= kMaxMembers,
               path << ": members = " << k << ", must be in [1, " << kMaxMembers << "]");
  if (file.metadata.contains("provenance")) d.provenance = file.metadata["provenance"];
  d.input = nn::GetNormalizer("input", file, path);
  d.delta = nn::GetNormalizer("delta", file, path);
  for (int m = 0; m < static_cast<int>(k); ++m) d.members.push_back(nn::GetMlp(MemberPrefix(m), file, path));
  d.Validate(path);
  return d;
}

Eigen::MatrixXd EnsembleDynamics::ReferenceNext(
    int member, const Eigen::Ref<const Eigen::MatrixXf>& states,
    const Eigen::Ref<const Eigen::MatrixXf>& actions) const {
  SECURE_CHECK(member >= 0 && member < num_members(),
               "EnsembleDynamics::ReferenceNext: member " << member << " of " << num_members());
  SECURE_CHECK(states.rows() == state_dim() && actions.rows() == action_dim() &&
                   states.cols() == actions.cols(),
               "EnsembleDynamics::ReferenceNext: states " << states.rows() << " x " << states.cols()
                   << ", actions " << actions.rows() << " x " << actions.cols() << ", model "
                   << state_dim() << " + " << action_dim());
  Eigen::MatrixXf x(state_dim() + action_dim(), states.cols());
  x.topRows(state_dim()) = states;
  x.bottomRows(action_dim()) = actions;
  const Eigen::MatrixXd y =
      nn::ReferenceForward(members[static_cast<std::size_t>(member)], input, x);
  Eigen::MatrixXd next = states.cast<double>();
  for (Eigen::Index j = 0; j < next.cols(); ++j)
    next.col(j) += delta.mean.cast<double>() + delta.scale.cast<double>().cwiseProduct(y.col(j));
  return next;
}

// ------------------------------------------------------------------------------------------------

EnsembleModel::EnsembleModel(std::shared_ptr<const EnsembleDynamics> model, int max_batch,
                             nn::MatmulBackend backend, PessimismOptions pessimism)
    : model_(std::move(model)), max_batch_(max_batch), pessimism_(pessimism) {
  pessimism_.Validate();
  SECURE_CHECK(model_ != nullptr, "EnsembleModel: no model");
  SECURE_CHECK(max_batch >= 1 && max_batch <= kMaxBatch,
               "EnsembleModel: max_batch = " << max_batch << ", must be in [1, " << kMaxBatch
                                             << "]");
  model_->Validate("learned dynamics");
  const int k = model_->num_members();
  const int d = model_->state_dim();
  for (const nn::MlpParams& m : model_->members) {
    nets_.emplace_back(m, model_->input, backend);
    workspaces_.push_back(nets_.back().MakeWorkspace(max_batch));
  }
  delta_mean_ = model_->delta.mean;
  delta_scale_ = model_->delta.scale;
  inputs_.resize(d + model_->action_dim(), max_batch);
  outputs_.resize(d, max_batch);
  members_.resize(d, static_cast<Eigen::Index>(k) * max_batch);
  mean_.resize(d, max_batch);
  offset_.resize(d);
  last_state_.resize(d);
}

std::string EnsembleModel::Describe() const {
  std::ostringstream out;
  out << "learned dynamics: ensemble of " << num_members() << " MLPs " << state_dim() << "+"
      << action_dim();
  for (int w : model_->members.front().spec.hidden) out << "-" << w;
  out << "-" << state_dim() << " (delta s)";
  return out.str();
}

void EnsembleModel::Predict(const Eigen::Ref<const Eigen::VectorXf>& state,
                            const Eigen::Ref<const Eigen::MatrixXf>& actions) const {
  const Eigen::Index m = actions.cols();
  SECURE_CHECK(m <= max_batch_, "learned dynamics: a batch of " << m
                                    << " actions exceeds the model's max_batch " << max_batch_);
  const int d = state_dim();
  auto x = inputs_.leftCols(m);
  x.topRows(d).colwise() = state;
  x.bottomRows(action_dim()) = actions;
  auto y = outputs_.leftCols(m);
  offset_ = delta_mean_ + state;  // preallocated: no temporary per member
  last_state_ = state;
  for (int k = 0; k < num_members(); ++k) {
    nets_[static_cast<std::size_t>(k)].Forward(x, workspaces_[static_cast<std::size_t>(k)], y);
    auto out = members_.middleCols(static_cast<Eigen::Index>(k) * m, m);
    out = y;
    out.array().colwise() *= delta_scale_.array();
    out.colwise() += offset_;
  }
  // The hold: member k steps again from its own prediction, the action unchanged.
  for (int step = 1; step < pessimism_.hold; ++step) {
    for (int k = 0; k < num_members(); ++k) {
      auto out = members_.middleCols(static_cast<Eigen::Index>(k) * m, m);
      x.topRows(d) = out;
      nets_[static_cast<std::size_t>(k)].Forward(x, workspaces_[static_cast<std::size_t>(k)], y);
      y.array().colwise() *= delta_scale_.array();
      y.colwise() += delta_mean_;
      out += y;
    }
  }
}

void EnsembleModel::StepMembers(const Eigen::Ref<const Eigen::VectorXf>& state,
                                const Eigen::Ref<const Eigen::MatrixXf>& actions,
                                Eigen::Ref<Eigen::MatrixXf> members) const {
  const Eigen::Index m = actions.cols();
  SECURE_CHECK(state.size() == state_dim() && actions.rows() == action_dim() &&
                   members.rows() == state_dim() && members.cols() == m * num_members(),
               "EnsembleModel::StepMembers: state " << state.size() << ", actions "
                   << actions.rows() << " x " << m << ", members " << members.rows() << " x "
                   << members.cols() << "; the model maps " << state_dim() << " + "
                   << action_dim() << " with " << num_members() << " members");
  Predict(state, actions);
  members = members_.leftCols(m * num_members());
  last_data_ = nullptr;  // no Step output to match
}

void EnsembleModel::DoStep(const Eigen::Ref<const Eigen::VectorXf>& state,
                           const Eigen::Ref<const Eigen::MatrixXf>& actions,
                           Eigen::Ref<Eigen::MatrixXf> next_states) const {
  Predict(state, actions);
  const Eigen::Index m = actions.cols();
  auto mean = mean_.leftCols(m);
  mean = members_.leftCols(m);
  for (int k = 1; k < num_members(); ++k) mean += members_.middleCols(k * m, m);
  mean *= 1.0f / static_cast<float>(num_members());
  next_states = mean;
  last_data_ = next_states.data();
  last_cols_ = m;
  last_stride_ = next_states.outerStride();
}

bool EnsembleModel::IsLastStep(const Eigen::Ref<const Eigen::MatrixXf>& states) const {
  if (last_data_ == nullptr || states.data() != last_data_ || states.cols() != last_cols_ ||
      states.outerStride() != last_stride_ || states.rows() != state_dim())
    return false;
  // The buffer may have been written since (e.g. by the shield's look-ahead): the values decide.
  return states == mean_.leftCols(last_cols_);
}

// ------------------------------------------------------------------------------------------------

PessimisticBarrier::PessimisticBarrier(std::unique_ptr<cbf::Barrier> inner,
                                       const EnsembleModel& model, PessimismOptions options)
    : inner_(std::move(inner)), model_(model), options_(options) {
  SECURE_CHECK(inner_ != nullptr, "PessimisticBarrier: no barrier");
  SECURE_CHECK(inner_->state_dim() == model.state_dim(),
               "PessimisticBarrier: the barrier reads " << inner_->state_dim()
                   << "-D states, the learned dynamics predicts " << model.state_dim() << "-D");
  options_.Validate();
  h_members_.resize(static_cast<Eigen::Index>(model.num_members()) * model.max_batch());
  gradient_state_.resize(model.state_dim());
  gradient_h_.resize(1);
  gradient_.resize(model.state_dim(), 1);
}

std::string PessimisticBarrier::Describe() const {
  return inner_->Describe() + ", " + options_.Describe() + " over the " +
         std::to_string(model_.num_members()) + " members of the learned dynamics";
}

void PessimisticBarrier::DoEvaluateStates(const Eigen::Ref<const Eigen::MatrixXf>& states,
                                          Eigen::Ref<Eigen::VectorXf> h, bool dense) {
  if (!model_.IsLastStep(states)) {
    if (dense)
      inner_->EvaluateDense(states, h);
    else
      inner_->Evaluate(states, h);
    return;
  }
  const Eigen::Index m = states.cols();
  const int k = model_.num_members();
  if (options_.linear && options_.aggregate == PessimismOptions::Aggregate::kMeanStd &&
      options_.kappa == 0) {
    // The members' first-order deviations through ∇h(s) average to zero around their mean, so
    // mean − 0·std is h(s̄⁺) itself: no gradient, no per-member values.
    if (dense)
      inner_->EvaluateDense(states, h);
    else
      inner_->Evaluate(states, h);
    return;
  }
  if (options_.linear) {
    LinearMembers(states, h, dense);
  } else if (dense) {
    inner_->EvaluateDense(model_.last_members(), h_members_.head(m * k));
  } else {
    inner_->Evaluate(model_.last_members(), h_members_.head(m * k));
  }
  AggregateMembers(m, h);
}

void PessimisticBarrier::DoEvaluateGradient(const Eigen::Ref<const Eigen::MatrixXf>& states,
                                            Eigen::Ref<Eigen::VectorXf> h,
                                            Eigen::Ref<Eigen::MatrixXf> gradients) {
  inner_->EvaluateGradient(states, h, gradients);
  if (model_.IsLastStep(states)) DoEvaluateStates(states, h, /*dense=*/false);
}

void PessimisticBarrier::LinearMembers(const Eigen::Ref<const Eigen::MatrixXf>& states,
                                       Eigen::Ref<Eigen::VectorXf> h, bool dense) {
  const Eigen::VectorXf& s = model_.last_state();
  if (!gradient_valid_ || gradient_state_ != s) {
    // One gradient per state s (a decision's rounds, probes and re-checks share it).
    inner_->EvaluateGradient(s, gradient_h_, gradient_);
    gradient_state_ = s;
    gradient_valid_ = gradient_.allFinite();
  }
  const Eigen::Index m = states.cols();
  const int k = model_.num_members();
  if (dense)
    inner_->EvaluateDense(states, h);  // h(s̄⁺) on the members' mean (the M states given)
  else
    inner_->Evaluate(states, h);
  const auto members = model_.last_members();
  // h_k = h(s̄⁺) + ∇h(s)·(s⁺_k − s̄⁺); the gradient's product with s̄⁺ once per action.
  for (Eigen::Index i = 0; i < m; ++i) {
    const float base = h[i] - gradient_.col(0).dot(states.col(i));
    for (int j = 0; j < k; ++j)
      h_members_[j * m + i] = base + gradient_.col(0).dot(members.col(j * m + i));
  }
  if (!gradient_valid_) h_members_.head(m * k).setConstant(std::numeric_limits<float>::quiet_NaN());
}

void PessimisticBarrier::AggregateMembers(Eigen::Index m, Eigen::Ref<Eigen::VectorXf> h) const {
  const int k = model_.num_members();
  const auto hm = h_members_.head(m * k);
  if (options_.aggregate == PessimismOptions::Aggregate::kMin) {
    h = hm.head(m);
    for (int j = 1; j < k; ++j) {
      const auto other = hm.segment(j * m, m);
      // NaN propagates: a NaN member makes h NaN (never safe).
      for (Eigen::Index i = 0; i < m; ++i)
        if (!std::isnan(h[i]) && !(other[i] >= h[i])) h[i] = other[i];
    }
    return;
  }
  // mean − κ std (population std, in double; a NaN member makes h NaN).
  for (Eigen::Index i = 0; i < m; ++i) {
    double sum = 0, sum_sq = 0;
    for (int j = 0; j < k; ++j) sum += hm[j * m + i];
    const double mean = sum / k;
    for (int j = 0; j < k; ++j) sum_sq += (hm[j * m + i] - mean) * (hm[j * m + i] - mean);
    h[i] = static_cast<float>(mean - options_.kappa * std::sqrt(sum_sq / k));
  }
}

std::unique_ptr<cbf::Barrier> ForShieldModel(std::unique_ptr<cbf::Barrier> barrier,
                                             const domains::DynamicsModel& dynamics) {
  const auto* ensemble = dynamic_cast<const EnsembleModel*>(&dynamics);
  if (ensemble == nullptr) return barrier;
  return std::make_unique<PessimisticBarrier>(std::move(barrier), *ensemble,
                                              ensemble->pessimism());
}

}  // namespace secure::dynamics
