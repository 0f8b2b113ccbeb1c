// experiments::ReadSection, the one reader of a domain's config section: the `domain:` key, then
// the preset (which follows the domain's options), then the other keys; errors name the file,
// the section and the field. (The commands that use it: tests/apps/cli_config_test.cc.)
#include <gtest/gtest.h>
#include <yaml-cpp/yaml.h>

#include <string>

#include "domains/double_integrator/domain.h"
#include "secure/experiments/config_section.h"
#include "tests/test_util.h"

namespace secure::experiments {
namespace {

using domains::double_integrator::DoubleIntegratorDomain;
using test::ErrorOf;

TEST(ReadSectionTest, WithoutTheSectionItIsThePreset) {
  DoubleIntegratorDomain domain(Profile::kQuick);
  const ExperimentOptions preset = domain.Preset();
  for (const char* text : {"", "double_integrator: {radius: 1.5}\n"}) {
    DoubleIntegratorDomain d(Profile::kQuick);
    const ExperimentOptions o = ReadSection(YAML::Load(text), "f.yaml", d);
    EXPECT_EQ(o.ToJson(), preset.ToJson()) << text;
  }
}

TEST(ReadSectionTest, TheSectionsKeysGoOverThePreset) {
  DoubleIntegratorDomain domain(Profile::kQuick);
  const ExperimentOptions preset = domain.Preset();
  const ExperimentOptions o = ReadSection(
      YAML::Load("pipeline:\n  shield: {class_k_gain: 5}\n  bc: {epochs: 3}\n"), "f.yaml", domain);
  EXPECT_EQ(o.shield.class_k_gain, 5.0);
  EXPECT_EQ(o.bc.epochs, 3);
  // The rest is the preset's.
  EXPECT_EQ(o.shield.num_samples, preset.shield.num_samples);
  EXPECT_EQ(o.seeds, preset.seeds);
}

TEST(ReadSectionTest, TheDomainKeyComesFirstSoThePresetFollowsIt) {
  // The preset's shield.dt is the domain's control period (task.dt): a file that changes the
  // period changes the shield's dt too, in every command.
  DoubleIntegratorDomain domain(Profile::kQuick);
  const double dt = domain.Preset().shield.dt;
  const ExperimentOptions o = ReadSection(
      YAML::Load("pipeline:\n  domain: {task: {dt: " + std::to_string(dt / 2) + "}}\n"),
      "f.yaml", domain);
  EXPECT_DOUBLE_EQ(o.shield.dt, dt / 2);
  EXPECT_DOUBLE_EQ(domain.OptionsJson()["task"]["dt"].get<double>(), dt / 2);
  // A shield key in the file still wins over the preset.
  DoubleIntegratorDomain other(Profile::kQuick);
  const ExperimentOptions p = ReadSection(
      YAML::Load("pipeline:\n  shield: {dt: 0.2}\n  domain: {task: {dt: 0.05}}\n"), "f.yaml",
      other);
  EXPECT_DOUBLE_EQ(p.shield.dt, 0.2);
}

TEST(ReadSectionTest, ErrorsNameTheFileTheSectionAndTheField) {
  DoubleIntegratorDomain a(Profile::kQuick);
  EXPECT_HAS(ErrorOf([&] { ReadSection(YAML::Load("pipeline: {sheild: {}}\n"), "f.yaml", a); }),
             "f.yaml [pipeline]: unknown section 'sheild'");
  DoubleIntegratorDomain b(Profile::kQuick);
  EXPECT_HAS(ErrorOf([&] {
               ReadSection(YAML::Load("pipeline:\n  domain: {task: {dt: -1}}\n"), "f.yaml", b);
             }),
             "f.yaml [pipeline] [domain]");
  DoubleIntegratorDomain c(Profile::kQuick);
  EXPECT_HAS(ErrorOf([&] { ReadSection(YAML::Load("pipeline: 3\n"), "f.yaml", c); }),
             "f.yaml:1: section 'pipeline' must be a mapping");
}

}  // namespace
}  // namespace secure::experiments
