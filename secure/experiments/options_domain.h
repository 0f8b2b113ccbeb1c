#pragma once
// The part of a Domain plug-in that is its options struct: held per profile, read from the
// domain's config section, validated and written as JSON. A plug-in whose options struct has
//   static Options For(Profile);  void Validate() const;
//   void ApplyYaml(const YAML::Node&, const std::string&);  nlohmann::json ToJson() const;
// derives from OptionsDomain<Options> and implements the rest of Domain.
#include "secure/experiments/domain.h"

namespace secure::experiments {

template <typename Options>
class OptionsDomain : public Domain {
 public:
  void ApplyYaml(const YAML::Node& node, const std::string& source) override {
    options_.ApplyYaml(node, source);
  }
  void Validate() const override { options_.Validate(); }
  nlohmann::json OptionsJson() const override { return options_.ToJson(); }

  const Options& options() const { return options_; }
  Options& mutable_options() { return options_; }

 protected:
  explicit OptionsDomain(Profile profile) : profile_(profile), options_(Options::For(profile)) {}

  Profile profile_;
  Options options_;
};

}  // namespace secure::experiments
