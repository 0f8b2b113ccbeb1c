#pragma once
// What the Franka plug-ins whose barrier data are drawn from scripted demonstrations share
// (panda-push, kitchen-cutting; coffee-placing's data are its participants'): their domain
// options' five parts (ArmDataOptions: task, shield_model, demonstrations, safe, near_dangerous),
// and one draw of their data (ArmDataDomain): the demonstrations from the stream `seed`, then,
// from Rng(seed + 1), the safe states and then the near-dangerous ones, by the plug-in's own
// generators (its ArmDataRecipe). GenerateData (seed = data_seed), CheckHeldOut (seed =
// data_seed ^ the plug-in's salt, `count` states per class) and the label check (the same draws as
// GenerateData) all take it. MuJoCo-free, so the plug-ins' public headers (domain.h) may include
// it.
#include <cstdint>
#include <functional>
#include <utility>
#include <vector>

#include "domains/franka/arm_domain.h"
#include "secure/common/error.h"
#include "secure/common/rng.h"
#include "secure/data/data.h"

namespace secure::domains::franka {

/// The parts of the domain options of a plug-in with scripted demonstrations. The plug-in's
/// options derive from it and add their own fields, For(profile) and their further checks.
template <typename Task, typename ShieldModel, typename Demonstrations, typename Safe,
          typename NearDangerous>
struct ArmDataOptions {
  using DemonstrationOptions = Demonstrations;
  using SafeOptions = Safe;
  using NearDangerousOptions = NearDangerous;

  Task task;
  ShieldModel shield_model;
  Demonstrations demonstrations;
  Safe safe;
  NearDangerous near_dangerous;

  /// The five parts' Validate(), in the order above.
  void ValidateParts() const {
    task.Validate();
    shield_model.Validate();
    demonstrations.Validate();
    safe.Validate();
    near_dangerous.Validate();
  }
  /// `fields` (a YamlFields; a template parameter so that this header needs no yaml-cpp) with the
  /// five parts' keys added: task, shield_model, demonstrations, safe, near_dangerous.
  template <typename Fields>
  Fields AddParts(Fields fields) {
    fields.Part("task", &task)
        .Part("shield_model", &shield_model)
        .Part("demonstrations", &demonstrations)
        .Part("safe", &safe)
        .Part("near_dangerous", &near_dangerous);
    return fields;
  }
};

/// A plug-in's generators (its data.h, with its task options bound), and its held-out stream.
template <typename Options, typename Demos, typename Scenario>
struct ArmDataRecipe {
  /// The demonstrations of these options (their seed set by the draw).
  std::function<Demos(const typename Options::DemonstrationOptions&)> demonstrate;
  /// CheckHeldOut's demonstration options for `count` states per class (null: as they are; e.g.
  /// at least `count` demonstration states where the safe states are drawn from them without
  /// replacement).
  std::function<void(long count, typename Options::DemonstrationOptions*)> fit_held_out;
  /// The safe states drawn from the demonstrations.
  std::function<data::StateSet(const Demos&, const typename Options::SafeOptions&, Rng&)> safe;
  /// The near-dangerous states (their generator's scenario per state in *scenarios, if not null).
  std::function<data::StateSet(const Demos&, const typename Options::NearDangerousOptions&, Rng&,
                               std::vector<Scenario>* scenarios)>
      near_dangerous;
  /// The attempts the demonstrator discarded.
  std::function<long(const Demos&)> discarded;
  /// CheckHeldOut draws from data_seed ^ held_out_salt (the training data: data_seed, + 1).
  std::uint64_t held_out_salt = 0;
};

/// One draw of a plug-in's data.
template <typename Demos, typename Scenario>
struct ArmDataDraw {
  Demos demos;
  data::StateSet safe, near_dangerous;
  std::vector<Scenario> scenarios;  // of near_dangerous's states (if asked for)
};

/// The base of a Franka plug-in's Domain with scripted demonstrations: ArmDomain<Options> with
/// GenerateData and CheckHeldOut from one draw by the plug-in's Recipe().
template <typename Options, typename Demos, typename Scenario>
class ArmDataDomain : public ArmDomain<Options> {
 public:
  using Recipe = ArmDataRecipe<Options, Demos, Scenario>;
  using Draw = ArmDataDraw<Demos, Scenario>;

  /// The options validated; the demonstrations from data_seed, the safe and near-dangerous
  /// states from data_seed + 1.
  experiments::DomainData GenerateData(std::uint64_t data_seed) const override {
    this->options_.Validate();
    const Recipe recipe = MakeRecipe();
    Draw draw = DrawData(recipe, data_seed, this->options_.demonstrations, this->options_.safe,
                         this->options_.near_dangerous, /*scenarios=*/false);
    experiments::DomainData d;
    d.demonstrations = draw.demos.trajectories;
    d.discarded_demonstrations = recipe.discarded(draw.demos);
    d.safe = std::move(draw.safe);
    d.near_dangerous = std::move(draw.near_dangerous);
    return d;
  }

  /// `count` safe and `count` near-dangerous states by the same generators from the stream
  /// data_seed ^ the recipe's held_out_salt, marked held out (MarkHeldOut).
  void CheckHeldOut(std::uint64_t data_seed, long count, data::StateSet* safe,
                    data::StateSet* near_dangerous) const override {
    this->options_.Validate();
    const Recipe recipe = MakeRecipe();
    typename Options::DemonstrationOptions demo_options = this->options_.demonstrations;
    if (recipe.fit_held_out) recipe.fit_held_out(count, &demo_options);
    typename Options::SafeOptions safe_options = this->options_.safe;
    safe_options.count = count;
    typename Options::NearDangerousOptions nd_options = this->options_.near_dangerous;
    nd_options.count = count;
    Draw draw = DrawData(recipe, data_seed ^ recipe.held_out_salt, demo_options, safe_options,
                         nd_options, /*scenarios=*/false);
    *safe = std::move(draw.safe);
    *near_dangerous = std::move(draw.near_dangerous);
    MarkHeldOut(data_seed, safe, near_dangerous);
  }

 protected:
  using ArmDomain<Options>::ArmDomain;

  /// The plug-in's generators, bound to its (valid) options.
  virtual Recipe MakeRecipe() const = 0;

  /// The label check's draw: the options validated, max_states checked (>= 1), then the same
  /// draws as GenerateData, with the near-dangerous states' scenarios.
  Draw LabelCheckDraw(std::uint64_t data_seed, long max_states) const {
    this->options_.Validate();
    SECURE_CHECK(max_states >= 1, "label check: max_states = " << max_states << ", must be >= 1");
    return DrawData(MakeRecipe(), data_seed, this->options_.demonstrations, this->options_.safe,
                    this->options_.near_dangerous, /*scenarios=*/true);
  }

 private:
  static Draw DrawData(const Recipe& recipe, std::uint64_t seed,
                       const typename Options::DemonstrationOptions& demonstrations,
                       const typename Options::SafeOptions& safe,
                       const typename Options::NearDangerousOptions& near_dangerous,
                       bool scenarios) {
    typename Options::DemonstrationOptions demo_options = demonstrations;
    demo_options.seed = seed;
    Draw draw{recipe.demonstrate(demo_options), {}, {}, {}};
    Rng rng(seed + 1);
    draw.safe = recipe.safe(draw.demos, safe, rng);
    draw.near_dangerous = recipe.near_dangerous(draw.demos, near_dangerous, rng,
                                                scenarios ? &draw.scenarios : nullptr);
    return draw;
  }
};

}  // namespace secure::domains::franka
