#include "secure/cbf/car_barrier_trainer.h"

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <set>
#include <sstream>

#include "secure/cbf/internal/car_barrier_torch.h"
#include "secure/cbf/internal/two_class_training.h"
#include "secure/common/error.h"
#include "secure/common/option_check.h"
#include "secure/common/progress.h"
#include "secure/common/rng.h"
#include "secure/common/strings.h"
#include "secure/common/timer.h"
#include "secure/common/yaml_value.h"
#include "secure/nn/model_file.h"
#include "secure/nn/torch_mlp.h"
#include "secure/nn/torch_threads.h"
#include "secure/nn/torch_training.h"
#include "secure/nn/training_loop.h"

namespace secure::cbf {
namespace {

std::string Describe(const data::StateSet& set, const std::string& what) {
  return set.source.empty() ? what : what + " (" + set.source + ")";
}

// The checks promised by TrainCarBarrier; `what` names the set.
void CheckObservations(const CarFeatureSpec& spec, const data::StateSet& set,
                       const std::string& what, bool near_dangerous) {
  const std::string name = Describe(set, what);
  const ObstacleLayout& l = spec.layout;
  SECURE_CHECK(set.size() > 0, name << ": 0 states; each set needs at least one");
  SECURE_CHECK(set.states.rows() == l.obs_dim,
               name << " have " << set.states.rows() << " features, the obstacle layout needs "
                    << "obs_dim = " << l.obs_dim);
  SECURE_CHECK(set.features.empty() || set.dim() == l.obs_dim,
               name << ": " << set.features.size() << " feature names for " << set.states.rows()
                    << " rows");
  for (Eigen::Index i = 0; i < set.states.cols(); ++i) {
    for (Eigen::Index f = 0; f < set.states.rows(); ++f) {
      const float v = set.states(f, i);
      SECURE_CHECK(std::isfinite(v), name << ": state " << i << ", feature "
                                          << (set.features.empty()
                                                  ? std::to_string(f)
                                                  : "'" + set.features[f] + "'")
                                          << " (row " << f << ") = " << v << ", must be finite");
    }
    if (!near_dangerous) continue;
    auto dist2 = [&](int j) {
      const float dx = set.states(l.PositionIndex(j), i), dy = set.states(l.PositionIndex(j) + 1, i);
      return static_cast<double>(dx) * dx + static_cast<double>(dy) * dy;
    };
    const double d0 = dist2(0);
    for (int j = 1; j < l.num_obstacles; ++j) {
      const double dj = dist2(j);
      SECURE_CHECK(dj >= d0 * (1.0 - 1e-5) - 1e-12,
                   name << ": state " << i << ": obstacle block " << j << " (distance "
                        << std::sqrt(dj) << ") is nearer than block 0 (distance " << std::sqrt(d0)
                        << "); the dangerous car must be block 0, with the obstacle blocks sorted "
                           "nearest first");
    }
    const double d0_eps = std::sqrt(d0 + spec.distance_epsilon);
    SECURE_CHECK(d0_eps <= spec.sensing_radius,
                 name << ": state " << i << ": the dangerous car (block 0) is at distance "
                      << d0_eps << ", beyond the sensing radius " << spec.sensing_radius
                      << ", so the barrier would ignore it");
  }
}


// Labelled observations as tensors.
struct Data {
  torch::Tensor features;  // [N, K, F] raw per-car features
  torch::Tensor in_range;  // [N, K] bool
  torch::Tensor danger;    // [N, K] float: the dangerous car of a near-dangerous state
  torch::Tensor safe;      // [N, K] float: every other in-range car
  torch::Tensor is_nd;     // [N] bool
  torch::Tensor weight;    // [N] per-state weight
  long n_safe = 0, n_nd = 0;
};

Data MakeData(const CarFeatureSpec& spec, const Eigen::MatrixXf& safe, const Eigen::MatrixXf& nd,
              double w_safe, double w_nd) {
  torch::NoGradGuard no_grad;
  Data d;
  d.n_safe = safe.cols();
  d.n_nd = nd.cols();
  const long n = d.n_safe + d.n_nd;
  Eigen::MatrixXf all(spec.layout.obs_dim, n);
  if (d.n_safe > 0) all.leftCols(d.n_safe) = safe;
  if (d.n_nd > 0) all.rightCols(d.n_nd) = nd;
  const internal::CarFeatureTensors f = internal::CarFeaturesTorch(spec, nn::ToTensor(all));
  d.features = f.features;
  d.in_range = f.in_range;
  d.is_nd = torch::cat({torch::zeros({d.n_safe}, torch::kBool), torch::ones({d.n_nd}, torch::kBool)});
  torch::Tensor first = torch::zeros({1, spec.layout.num_obstacles}, torch::kBool);
  first.index_put_({0, 0}, true);
  const torch::Tensor danger = d.in_range & d.is_nd.unsqueeze(1) & first;
  d.danger = danger.to(torch::kFloat32);
  d.safe = (d.in_range & torch::logical_not(danger)).to(torch::kFloat32);
  d.weight = torch::cat({torch::full({d.n_safe}, w_safe), torch::full({d.n_nd}, w_nd)})
                 .to(torch::kFloat32);
  return d;
}

// Per-state loss, weighted mean over the states.
torch::Tensor Loss(const torch::Tensor& entry_h, const torch::Tensor& danger,
                   const torch::Tensor& safe, const torch::Tensor& weight,
                   const CarBarrierTrainerOptions& o) {
  const torch::Tensor td = (torch::relu(entry_h + o.danger_margin) * danger).sum(1) /
                           danger.sum(1).clamp_min(1.0);
  const torch::Tensor ts =
      (torch::relu(o.safe_margin - entry_h) * safe).sum(1) / safe.sum(1).clamp_min(1.0);
  const torch::Tensor per_state = o.danger_weight * td + o.safe_weight * ts;
  return (weight * per_state).sum() / weight.sum();
}

double Fraction(const torch::Tensor& hits, const torch::Tensor& of) {
  const double n = of.sum().item<double>();
  return n > 0 ? (hits & of).sum().item<double>() / n : 0.0;
}

struct Score {
  double loss = 0.0;
  CarBarrierAccuracy accuracy;
};

Score Evaluate(internal::CarBarrierTorch& model, const Data& d, const CarBarrierTrainerOptions& o) {
  torch::NoGradGuard no_grad;
  Score s;
  if (d.n_safe + d.n_nd == 0) return s;
  const torch::Tensor entry_h = model->EntryValues(d.features);
  s.loss = Loss(entry_h, d.danger, d.safe, d.weight, o).item<double>();
  const torch::Tensor h = internal::CappedMinTorch(entry_h, d.in_range, model->cap());
  const torch::Tensor is_safe = torch::logical_not(d.is_nd);
  s.accuracy.states.safe = Fraction(h >= 0, is_safe);
  s.accuracy.states.near_dangerous = Fraction(h < 0, d.is_nd);
  s.accuracy.entries.safe = Fraction(entry_h >= 0, d.safe > 0);
  s.accuracy.entries.near_dangerous = Fraction(entry_h < 0, d.danger > 0);
  return s;
}

bool Better(const Score& a, const Score& b) {
  const double da = a.accuracy.states.Balanced(), db = b.accuracy.states.Balanced();
  if (da != db) return da > db;
  return a.loss < b.loss;
}

nlohmann::json AccuracyJson(const ClassAccuracy& a) {
  return {{"safe", a.safe}, {"near_dangerous", a.near_dangerous}, {"balanced", a.Balanced()}};
}

}  // namespace

// ------------------------------------------------------------------------------------------------
// Options

CarBarrierTrainerOptions CarBarrierTrainerOptions::Released() {
  CarBarrierTrainerOptions o;
  o.danger_margin = 0.01;
  o.safe_margin = 0.002;
  o.danger_weight = 2.0;
  o.safe_weight = 1.0;
  o.learning_rate = 1e-4;
  o.final_learning_rate = 1e-4;
  o.weight_decay = 1e-8;
  o.batch_size = 4;
  o.max_epochs = 1;
  o.validation_fraction = 0.0;
  o.normalize_inputs = false;
  return o;
}

void CarBarrierTrainerOptions::Validate() const {
  // An unset layout passes here (a domain whose barrier is flat carries these options unused);
  // TrainCarBarrier requires it.
  input.Validate("CarBarrierTrainerOptions::input", /*allow_unset_layout=*/true);
  CheckLayerWidths(hidden, "CarBarrierTrainerOptions", "hidden");
  if (cap.has_value())
    SECURE_CHECK_FIELD(std::isfinite(*cap) && *cap >= 0, "CarBarrierTrainerOptions", "cap", *cap,
                       ">= 0 (or unset: the safe margin)");
  SECURE_CHECK_FIELD(std::isfinite(danger_margin) && danger_margin >= 0, "CarBarrierTrainerOptions",
                     "danger_margin", danger_margin, ">= 0");
  SECURE_CHECK_FIELD(std::isfinite(safe_margin) && safe_margin >= 0, "CarBarrierTrainerOptions",
                     "safe_margin", safe_margin, ">= 0");
  SECURE_CHECK_FIELD(std::isfinite(danger_weight) && danger_weight > 0, "CarBarrierTrainerOptions",
                     "danger_weight", danger_weight, "> 0");
  SECURE_CHECK_FIELD(std::isfinite(safe_weight) && safe_weight > 0, "CarBarrierTrainerOptions",
                     "safe_weight", safe_weight, "> 0");
  ValidateSchedule("CarBarrierTrainerOptions");
}

void CarBarrierTrainerOptions::ApplyYaml(const YAML::Node& node, const std::string& source) {
  static const std::set<std::string> known = [] {
    std::set<std::string> k = {"layout",           "collision_radius", "sensing_radius",
                               "distance_epsilon", "use_velocity",     "hidden",
                               "activation",       "normalize_inputs", "cap",
                               "danger_margin",    "safe_margin",      "danger_weight",
                               "safe_weight",      "balance_classes"};
    k.insert(Keys().begin(), Keys().end());
    return k;
  }();
  const auto apply = [&](const std::string& key, const YAML::Node& v) {
    if (key == "layout") {
      SECURE_CHECK(v.IsMap(), source << ": field 'layout' must be a mapping");
      for (const auto& l : v) {
        const std::string lk = YamlKey(l.first, source);
        const auto field =
            std::find_if(ObstacleLayout::kFields.begin(), ObstacleLayout::kFields.end(),
                         [&](const ObstacleLayout::Field& f) { return lk == f.name; });
        SECURE_CHECK(field != ObstacleLayout::kFields.end(),
                     source << ": unknown field 'layout." << lk << "' in the car barrier options");
        input.layout.*field->member = YamlValue<int>(l.second, "layout." + lk, source);
      }
    } else if (key == "collision_radius") {
      input.collision_radius = YamlValue<double>(v, key, source);
    } else if (key == "sensing_radius") {
      input.sensing_radius = YamlValue<double>(v, key, source);
    } else if (key == "distance_epsilon") {
      input.distance_epsilon = YamlValue<double>(v, key, source);
    } else if (key == "use_velocity") {
      input.use_velocity = YamlValue<bool>(v, key, source);
    } else if (key == "hidden") {
      hidden = YamlWidths(v, key, source);
    } else if (key == "activation") {
      activation = FromString(nn::kActivationNames, YamlValue<std::string>(v, key, source),
                              source + ": activation");
    } else if (key == "normalize_inputs") {
      normalize_inputs = YamlValue<bool>(v, key, source);
    } else if (key == "cap") {
      if (v.IsNull())
        cap.reset();
      else
        cap = YamlValue<double>(v, key, source);
    } else if (key == "danger_margin") {
      danger_margin = YamlValue<double>(v, key, source);
    } else if (key == "safe_margin") {
      safe_margin = YamlValue<double>(v, key, source);
    } else if (key == "danger_weight") {
      danger_weight = YamlValue<double>(v, key, source);
    } else if (key == "safe_weight") {
      safe_weight = YamlValue<double>(v, key, source);
    } else if (key == "balance_classes") {
      balance_classes = YamlValue<bool>(v, key, source);
    } else {
      ApplyYamlKey(key, v, source);
    }
  };
  ForEachYamlField(node, known, "car barrier trainer options", source, apply);
}

nlohmann::json CarBarrierTrainerOptions::ToJson() const {
  nlohmann::json j = {{"input", input.ToJson()},
                      {"hidden", hidden},
                      {"activation", ToString(nn::kActivationNames, activation)},
                      {"normalize_inputs", normalize_inputs},
                      {"cap", cap.has_value() ? nlohmann::json(*cap) : nlohmann::json(nullptr)},
                      {"effective_cap", EffectiveCap()},
                      {"danger_margin", danger_margin},
                      {"safe_margin", safe_margin},
                      {"danger_weight", danger_weight},
                      {"safe_weight", safe_weight},
                      {"balance_classes", balance_classes}};
  AddJson(&j);
  return j;
}

// ------------------------------------------------------------------------------------------------
// Summary

nlohmann::json CarBarrierAccuracy::ToJson() const {
  return {{"states", AccuracyJson(states)}, {"entries", AccuracyJson(entries)}};
}

std::string CarBarrierTrainingSummary::BriefReport() const {
  char line[320];
  std::snprintf(line, sizeof line,
                "epochs %d (best %d, %s), %ld steps, state acc train safe %.4f nd %.4f / val safe "
                "%.4f nd %.4f, entry acc val safe %.4f danger %.4f, %.2f s",
                epochs, best_epoch, stop_reason.c_str(), iterations, train_accuracy.states.safe,
                train_accuracy.states.near_dangerous, validation_accuracy.states.safe,
                validation_accuracy.states.near_dangerous, validation_accuracy.entries.safe,
                validation_accuracy.entries.near_dangerous, wall_seconds);
  return line;
}

std::string CarBarrierTrainingSummary::FullReport() const {
  std::ostringstream s;
  char buf[256];
  s << "| split | safe states | nd states | safe cars | dangerous cars | loss | state acc safe | "
       "state acc nd | car acc safe | car acc dangerous |\n"
    << "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n";
  auto row = [&](const char* name, long ns, long nn_, long es, long ed, double loss,
                 const CarBarrierAccuracy& a) {
    std::snprintf(buf, sizeof buf, "| %s | %ld | %ld | %ld | %ld | %.5f | %.4f | %.4f | %.4f | %.4f |\n",
                  name, ns, nn_, es, ed, loss, a.states.safe, a.states.near_dangerous,
                  a.entries.safe, a.entries.near_dangerous);
    s << buf;
  };
  row("train", train_safe, train_near_dangerous, train_safe_entries, train_danger_entries,
      train_loss, train_accuracy);
  row("validation", validation_safe, validation_near_dangerous, validation_safe_entries,
      validation_danger_entries, validation_loss, validation_accuracy);
  std::snprintf(buf, sizeof buf, "epochs %d, best epoch %d, stop: %s, %ld steps, cap %g, %.2f s\n",
                epochs, best_epoch, stop_reason.c_str(), iterations, cap, wall_seconds);
  s << buf;
  return s.str();
}

nlohmann::json CarBarrierTrainingSummary::ToJson() const {
  return {{"epochs", epochs},
          {"best_epoch", best_epoch},
          {"iterations", iterations},
          {"train_loss", train_loss},
          {"validation_loss", validation_loss},
          {"train_accuracy", train_accuracy.ToJson()},
          {"validation_accuracy", validation_accuracy.ToJson()},
          {"train_counts",
           {{"safe", train_safe},
            {"near_dangerous", train_near_dangerous},
            {"safe_entries", train_safe_entries},
            {"danger_entries", train_danger_entries}}},
          {"validation_counts",
           {{"safe", validation_safe},
            {"near_dangerous", validation_near_dangerous},
            {"safe_entries", validation_safe_entries},
            {"danger_entries", validation_danger_entries}}},
          {"cap", cap},
          {"wall_seconds", wall_seconds},
          {"stop_reason", stop_reason}};
}

// ------------------------------------------------------------------------------------------------
// Evaluation with the Eigen path

CarBarrierAccuracy EvaluateCarBarrier(const CarBarrierNet& net, const data::StateSet& safe,
                                      const data::StateSet& near_dangerous) {
  net.Validate();
  CheckObservations(net.input, safe, "safe states", false);
  CheckObservations(net.input, near_dangerous, "near-dangerous states", true);
  CarBarrierAccuracy a;
  auto evaluator = net.MakeEvaluator();
  const int k = net.input.layout.num_obstacles;
  long safe_entries = 0, safe_ok = 0, danger_entries = 0, danger_ok = 0;
  for (int pass = 0; pass < 2; ++pass) {
    const data::StateSet& set = pass == 0 ? safe : near_dangerous;
    Eigen::VectorXf h(set.size());
    evaluator->Evaluate(set.states, h);
    const long hits = pass == 0 ? (h.array() >= 0).count() : (h.array() < 0).count();
    (pass == 0 ? a.states.safe : a.states.near_dangerous) =
        static_cast<double>(hits) / static_cast<double>(set.size());
    const Eigen::MatrixXf entries = net.EntryValues(set.states);
    for (Eigen::Index i = 0; i < entries.cols(); ++i) {
      for (int j = 0; j < k; ++j) {
        const float v = entries(j, i);
        if (std::isinf(v) && v > 0) continue;  // out of range
        if (pass == 1 && j == 0) {
          ++danger_entries;
          danger_ok += v < 0;
        } else {
          ++safe_entries;
          safe_ok += v >= 0;
        }
      }
    }
  }
  a.entries.safe = safe_entries ? static_cast<double>(safe_ok) / safe_entries : 0.0;
  a.entries.near_dangerous = danger_entries ? static_cast<double>(danger_ok) / danger_entries : 0.0;
  return a;
}

// ------------------------------------------------------------------------------------------------
// Training

CarBarrierNet TrainCarBarrier(const CarBarrierTrainerOptions& options, const data::StateSet& safe,
                              const data::StateSet& near_dangerous,
                              CarBarrierTrainingSummary* summary,
                              const CarBarrierEpochCallback& callback) {
  options.Validate();
  options.input.Validate("CarBarrierTrainerOptions::input");  // the layout must be given
  CheckObservations(options.input, safe, "safe states", false);
  CheckObservations(options.input, near_dangerous, "near-dangerous states", true);
  SECURE_CHECK(safe.features == near_dangerous.features,
               Describe(safe, "safe states") << " and " << Describe(near_dangerous, "near-dangerous states")
                                             << " have different feature names");
  const Stopwatch clock;
  const nn::ScopedTorchThreads threads(options.threads);
  Rng rng(options.seed);

  const internal::TwoClassSplit split(safe, near_dangerous, options.validation_fraction, rng);

  const double n_train = static_cast<double>(split.train_safe.cols() + split.train_nd.cols());
  double w_safe = 1.0, w_nd = 1.0;
  if (options.balance_classes) {
    w_safe = n_train / (2.0 * static_cast<double>(split.train_safe.cols()));
    w_nd = n_train / (2.0 * static_cast<double>(split.train_nd.cols()));
  }
  const Data train = MakeData(options.input, split.train_safe, split.train_nd, w_safe, w_nd);
  const Data val = MakeData(options.input, split.val_safe, split.val_nd, w_safe, w_nd);

  // Normaliser on the in-range training entries.
  const int fdim = options.input.feature_dim();
  nn::Normalizer normalizer = nn::Normalizer::Identity(fdim);
  long n_entries = train.in_range.sum().item<long>();
  if (options.normalize_inputs && n_entries > 0) {
    const torch::Tensor in = train.features.reshape({-1, fdim})
                                 .index({train.in_range.reshape({-1})})
                                 .contiguous();
    normalizer = nn::Normalizer::Fit(nn::ToEigen(in));
  }

  nn::MlpSpec spec;
  spec.input_dim = fdim;
  spec.hidden = options.hidden;
  spec.output_dim = 1;
  spec.activation = options.activation;
  const double cap = options.EffectiveCap();
  // Initial weights from the seed, through a generator of their own (never LibTorch's global
  // one): concurrent trainings need no lock.
  internal::CarBarrierTorch model(options.input, spec, normalizer, cap);
  model->LoadMlpParams(nn::TorchMlp(spec, options.seed)->ToParams());
  torch::optim::Adam optimizer(
      model->parameters(),
      torch::optim::AdamOptions(options.learning_rate).weight_decay(options.weight_decay));

  CarBarrierTrainingSummary s;
  s.train_safe = train.n_safe;
  s.train_near_dangerous = train.n_nd;
  s.validation_safe = val.n_safe;
  s.validation_near_dangerous = val.n_nd;
  s.train_safe_entries = train.safe.sum().item<long>();
  s.train_danger_entries = train.danger.sum().item<long>();
  if (split.has_validation) {
    s.validation_safe_entries = val.safe.sum().item<long>();
    s.validation_danger_entries = val.danger.sum().item<long>();
  }
  s.cap = cap;
  nn::MlpParams best_params;

  const nn::TrainingLoopOptions loop =
      options.LoopOptions(train.n_safe + train.n_nd, "cbf::TrainCarBarrier");
  nn::TrainingSteps<Score> steps;
  nn::UseAdam(
      optimizer,
      [&](const torch::Tensor& idx) {
        const torch::Tensor entry_h = model->EntryValues(train.features.index_select(0, idx));
        return Loss(entry_h, train.danger.index_select(0, idx), train.safe.index_select(0, idx),
                    train.weight.index_select(0, idx), options);
      },
      &steps);
  steps.evaluate = [&](int) {
    return Evaluate(model, split.has_validation ? val : train, options);
  };
  steps.better = Better;
  steps.save_best = [&] { best_params = model->MlpParams(); };
  steps.restore_best = [&] { model->LoadMlpParams(best_params); };
  steps.on_epoch = [&](const nn::EpochReport<Score>& r) {
    if (options.verbose && (r.epoch % 10 == 0 || r.epoch == options.max_epochs)) {
      PrintStatusLineF("[car cbf train] epoch %d/%d loss %.5f %s state acc %.4f (best %.4f @ %d)\n",
                       r.epoch, options.max_epochs, r.train_loss,
                       split.has_validation ? "val" : "train", r.score->accuracy.states.Balanced(),
                       r.best->accuracy.states.Balanced(), r.best_epoch);
    }
    if (callback && !callback(r.epoch, r.train_loss, r.score->accuracy.states.Balanced()))
      return nn::EpochDecision::kStop;
    return nn::EpochDecision::kContinue;
  };
  const nn::TrainingLoopResult result = nn::RunTrainingLoop(loop, rng, steps);
  internal::RecordLoop(result, &s);

  const Score train_score = Evaluate(model, train, options);
  s.train_loss = train_score.loss;
  s.train_accuracy = train_score.accuracy;
  if (split.has_validation) {
    const Score val_score = Evaluate(model, val, options);
    s.validation_loss = val_score.loss;
    s.validation_accuracy = val_score.accuracy;
  }
  s.wall_seconds = clock.Seconds();

  CarBarrierNet net = model->ToNet();
  net.features = safe.features;
  // The summary without its wall-clock time: same seed and data, same model file bytes.
  net.provenance =
      internal::TrainingProvenance("secure::cbf::TrainCarBarrier (per-car hinge loss, §3.1)",
                                   options.ToJson(), s.ToJson(), safe, near_dangerous);
  net.Validate();
  if (summary != nullptr) *summary = s;
  return net;
}

}  // namespace secure::cbf
