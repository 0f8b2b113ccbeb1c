// The shield's options and its decision record (shield.h): ShieldOptions (Validate, ToJson,
// ApplyYaml), Decision::ToJson and the class-K function alpha(h).
#include <cmath>

#include "secure/common/error.h"
#include "secure/common/limits.h"
#include "secure/common/option_check.h"
#include "secure/common/yaml_fields.h"
#include "secure/shield/shield.h"

namespace secure::shield {

void ShieldOptions::Validate() const {
  SECURE_CHECK_FIELD(num_samples > 0, "ShieldOptions", "num_samples", num_samples, "> 0");
  SECURE_CHECK_FIELD(num_samples <= kMaxShieldSamples, "ShieldOptions", "num_samples", num_samples,
                     "in [1, " << kMaxShieldSamples << "]");
  SECURE_CHECK_FIELD(std::isfinite(safe_ratio) && safe_ratio >= 0 && safe_ratio < 1,
                     "ShieldOptions", "safe_ratio", safe_ratio, "in [0, 1)");
  SECURE_CHECK_FIELD(std::isfinite(dt) && dt > 0, "ShieldOptions", "dt", dt, "> 0");
  SECURE_CHECK_FIELD(std::isfinite(class_k_gain) && class_k_gain > 0, "ShieldOptions",
                     "class_k_gain", class_k_gain, "> 0 (alpha must be strictly increasing)");
  SECURE_CHECK_FIELD(num_probes > 0, "ShieldOptions", "num_probes", num_probes, "> 0");
  SECURE_CHECK_FIELD(num_probes <= kMaxShieldSamples, "ShieldOptions", "num_probes", num_probes,
                     "in [1, " << kMaxShieldSamples << "]");
  SECURE_CHECK_FIELD(std::isfinite(probe_extent) && probe_extent > 0, "ShieldOptions",
                     "probe_extent", probe_extent, "> 0");
  SECURE_CHECK_FIELD(std::isfinite(sigma_step) && sigma_step > 0, "ShieldOptions", "sigma_step",
                     sigma_step, "> 0");
  SECURE_CHECK_FIELD(max_iterations > 0, "ShieldOptions", "max_iterations", max_iterations, "> 0");
  SECURE_CHECK_FIELD(std::isfinite(time_budget_us) && time_budget_us >= 0, "ShieldOptions",
                     "time_budget_us", time_budget_us, ">= 0");
  SECURE_CHECK_FIELD(std::isfinite(top_q_fraction) && top_q_fraction > 0 && top_q_fraction <= 1,
                     "ShieldOptions", "top_q_fraction", top_q_fraction, "in (0, 1]");
  SECURE_CHECK_FIELD(lookahead_steps >= 1 && lookahead_steps <= kMaxLookaheadSteps, "ShieldOptions",
                     "lookahead_steps", lookahead_steps, "in [1, " << kMaxLookaheadSteps << "]");
  SECURE_CHECK_FIELD(qp_iterations >= 1 && qp_iterations <= kMaxQpIterations, "ShieldOptions",
                     "qp_iterations", qp_iterations, "in [1, " << kMaxQpIterations << "]");
  SECURE_CHECK_FIELD(qp_line_search >= 0 && qp_line_search <= kMaxQpLineSearch, "ShieldOptions",
                     "qp_line_search", qp_line_search, "in [0, " << kMaxQpLineSearch << "]");
  SECURE_CHECK_FIELD(qp_bisection >= 0 && qp_bisection <= kMaxQpBisection, "ShieldOptions",
                     "qp_bisection", qp_bisection, "in [0, " << kMaxQpBisection << "]");
  SECURE_CHECK_FIELD(std::isfinite(qp_margin) && qp_margin >= 0, "ShieldOptions", "qp_margin",
                     qp_margin, ">= 0");
  SECURE_CHECK_FIELD(std::isfinite(qp_max_step) && qp_max_step >= 0, "ShieldOptions",
                     "qp_max_step", qp_max_step, ">= 0 (0: no limit)");
  SECURE_CHECK_FIELD(std::isfinite(qp_smoothing) && qp_smoothing >= 0, "ShieldOptions",
                     "qp_smoothing", qp_smoothing, ">= 0 (0: off)");
  SECURE_CHECK_FIELD(refine_steps >= 1 && refine_steps <= kMaxRefineSteps, "ShieldOptions",
                     "refine_steps", refine_steps, "in [1, " << kMaxRefineSteps << "]");
  SECURE_CHECK(qp_target == QpTarget::kBoundary || qp_metric == QpMetric::kPolicy,
               "ShieldOptions::qp_target = safe-mean is the mean of the policy's Gaussian over the "
               "linearised half-space, a projection in the policy's metric: it needs qp_metric = "
               "policy, not "
                   << ToString(kQpMetricNames, qp_metric));
  SECURE_CHECK(proposal == Proposal::kNone || lookahead_steps == 1,
               "ShieldOptions::proposal = " << ToString(kProposalNames, proposal)
                                            << " linearises the one-step condition: it needs "
                                               "lookahead_steps = 1, not "
                                            << lookahead_steps);
}

void ShieldOptions::Validate(int action_dim) const {
  Validate();
  SECURE_CHECK(sampler != Sampler::kQmc || action_dim <= MaxQmcDimension(),
               "ShieldOptions::sampler = qmc supports action dimensions up to "
                   << MaxQmcDimension()
                   << " (Boost.Random's Sobol tables); the action dimension is " << action_dim
                   << ": use sampler = iid or antithetic");
}

nlohmann::json ShieldOptions::ToJson() const {
  nlohmann::json json = {{"num_samples", num_samples},
                         {"safe_ratio", safe_ratio},
                         {"dt", dt},
                         {"class_k", ToString(kClassKNames, class_k)},
                         {"class_k_gain", class_k_gain},
                         {"aggregation", ToString(kAggregationNames, aggregation)},
                         {"resampling", ToString(kResamplingNames, resampling)},
                         {"num_probes", num_probes},
                         {"probe_extent", probe_extent},
                         {"sigma_step", sigma_step},
                         {"max_iterations", max_iterations},
                         {"time_budget_us", time_budget_us},
                         {"seed", seed},
                         {"sampler", ToString(kSamplerNames, sampler)},
                         {"action_bounds", ToString(kActionBoundsNames, action_bounds)}};
  // Only where it acts, so that the options of every other shield keep their identity (run
  // directories compare them).
  if (aggregation == Aggregation::kTopQ) json["top_q_fraction"] = top_q_fraction;
  if (lookahead_steps != 1) json["lookahead_steps"] = lookahead_steps;
  if (proposal != Proposal::kNone) {
    json["proposal"] = ToString(kProposalNames, proposal);
    if (proposal == Proposal::kRefine) {
      json["refine_steps"] = refine_steps;
    } else {
      json["qp_iterations"] = qp_iterations;
      // (absent: none, as before it existed)
      if (qp_line_search > 0) json["qp_line_search"] = qp_line_search;
      if (qp_bisection > 0) json["qp_bisection"] = qp_bisection;
    }
    json["qp_margin"] = qp_margin;
    // (absent: no limit, as before; it acts only with proposal = qp)
    if (qp_max_step > 0 && proposal == Proposal::kQp) json["qp_max_step"] = qp_max_step;
    if (qp_smoothing > 0 && proposal == Proposal::kQp) json["qp_smoothing"] = qp_smoothing;
  }
  // Absent when euclidean (every shield before it keeps its bytes); written whenever set, also
  // with proposal none: a config sets it for every method and secure-qp / cbf-qp take it from
  // these options (and a result's options then say which metric its projections used).
  if (qp_metric != QpMetric::kEuclidean) json["qp_metric"] = ToString(kQpMetricNames, qp_metric);
  if (qp_target != QpTarget::kBoundary) json["qp_target"] = ToString(kQpTargetNames, qp_target);
  return json;
}

void ShieldOptions::ApplyYaml(const YAML::Node& node, const std::string& source) {
  YamlFields()
      .Field("num_samples", &num_samples)
      .Field("safe_ratio", &safe_ratio)
      .Field("dt", &dt)
      .Enum("class_k", &class_k, kClassKNames)
      .Field("class_k_gain", &class_k_gain)
      .Enum("aggregation", &aggregation, kAggregationNames)
      .Enum("resampling", &resampling, kResamplingNames)
      .Field("num_probes", &num_probes)
      .Field("probe_extent", &probe_extent)
      .Field("sigma_step", &sigma_step)
      .Field("max_iterations", &max_iterations)
      .Field("time_budget_us", &time_budget_us)
      .Field("seed", &seed)
      .Enum("sampler", &sampler, kSamplerNames)
      .Field("top_q_fraction", &top_q_fraction)
      .Field("lookahead_steps", &lookahead_steps)
      .Enum("action_bounds", &action_bounds, kActionBoundsNames)
      .Enum("proposal", &proposal, kProposalNames)
      .Field("qp_iterations", &qp_iterations)
      .Field("qp_line_search", &qp_line_search)
      .Field("qp_bisection", &qp_bisection)
      .Field("qp_margin", &qp_margin)
      .Field("qp_max_step", &qp_max_step)
      .Field("qp_smoothing", &qp_smoothing)
      .Enum("qp_metric", &qp_metric, kQpMetricNames)
      .Enum("qp_target", &qp_target, kQpTargetNames)
      .Field("refine_steps", &refine_steps)
      .Apply(node, source);
}

nlohmann::json Decision::ToJson() const {
  nlohmann::json a = nlohmann::json::array();
  for (Eigen::Index i = 0; i < action.size(); ++i) a.push_back(action[i]);
  nlohmann::json json = {{"status", ToString(kStatusNames, status)},
          {"action", a},
          {"g", g},
          {"h", h},
          {"iterations", iterations},
          {"safe_ratio", safe_ratio},
          {"intervened", intervened},
          {"distance_to_mean", distance_to_mean},
          {"bounded", bounded},
          {"fallback", ToString(kFallbackNames, fallback)},
          {"seconds", seconds}};
  if (qp != QpOutcome::kNotTried) json["qp"] = ToString(kQpOutcomeNames, qp);
  return json;
}

double ClassKValue(const ShieldOptions& options, double h) {
  switch (options.class_k) {
    case ClassK::kLinear:
      return options.class_k_gain * h;
    case ClassK::kCubic:
      return options.class_k_gain * h * h * h;
  }
  SECURE_INTERNAL_CHECK(false, "unknown class-K function");
}

}  // namespace secure::shield
