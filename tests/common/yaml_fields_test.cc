// YamlFields: the field table behind ApplyYaml.
#include "secure/common/yaml_fields.h"

#include <gtest/gtest.h>

#include "tests/test_util.h"

namespace secure {
namespace {

using test::ErrorOf;

struct Options {
  long count = 1;
  double rate = 0.5;
  bool on = false;
  struct {
    int depth = 2;
  } nested;
};

YamlFields Table(Options* o) {
  return YamlFields()
      .Field("count", &o->count)
      .Field("rate", &o->rate)
      .Field("on", &o->on)
      .Section("nested", YamlFields().Field("depth", &o->nested.depth));
}

TEST(YamlFieldsTest, SetsTheGivenFieldsAndLeavesTheOthers) {
  Options o;
  Table(&o).Apply(YAML::Load("{count: 7, nested: {depth: 4}}"), "x.yaml");
  EXPECT_EQ(o.count, 7);
  EXPECT_EQ(o.rate, 0.5);
  EXPECT_FALSE(o.on);
  EXPECT_EQ(o.nested.depth, 4);
}

TEST(YamlFieldsTest, UnknownKeysWrongTypesAndNonMappingsNameTheSource) {
  Options o;
  EXPECT_HAS(ErrorOf([&] { Table(&o).Apply(YAML::Load("{cont: 7}"), "x.yaml"); }),
             "x.yaml: unknown key 'cont' (valid: count, rate, on, nested)");
  EXPECT_HAS(ErrorOf([&] { Table(&o).Apply(YAML::Load("{nested: {deep: 1}}"), "x.yaml"); }),
             "x.yaml [nested]: unknown key 'deep' (valid: depth)");
  EXPECT_HAS(ErrorOf([&] { Table(&o).Apply(YAML::Load("{rate: fast}"), "x.yaml"); }),
             "field 'rate' has value 'fast', which is not a valid number");
  EXPECT_HAS(ErrorOf([&] { Table(&o).Apply(YAML::Load("[1, 2]"), "x.yaml"); }),
             "x.yaml: expected a mapping");
  EXPECT_HAS(ErrorOf([&] { Table(&o).Apply(YAML::Load("{nested: 3}"), "x.yaml"); }),
             "x.yaml [nested]: expected a mapping");
  EXPECT_EQ(o.count, 1);  // nothing before the error was applied in these cases
}

}  // namespace
}  // namespace secure
