// secure demos convert IN OUT: demonstrations and state sets between CSV and robomimic's HDF5
// layout (by extension: .csv, .h5 / .hdf5; see docs/FILE_FORMATS.md).
#include <algorithm>
#include <cctype>
#include <filesystem>
#include <iostream>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "commands.h"
#include "secure/common/error.h"
#include "secure/common/strings.h"
#include "secure/data/data.h"
#include "secure/experiments/domain.h"

namespace secure::cli {
namespace {

// Expands the names of `select` against CSV columns: a name that is no column but whose
// "<name>[0]", "<name>[1]", ... are stands for them (as an obs key does in an HDF5 file).
std::vector<std::string> ExpandKeys(const std::vector<std::string>& columns,
                                    const std::vector<std::string>& select) {
  const auto has = [&](const std::string& name) {
    return std::find(columns.begin(), columns.end(), name) != columns.end();
  };
  std::vector<std::string> out;
  for (const std::string& name : select) {
    if (has(name) || !has(name + "[0]")) {
      out.push_back(name);  // a missing name is reported by the reader
      continue;
    }
    for (long j = 0; has(name + "[" + std::to_string(j) + "]"); ++j)
      out.push_back(name + "[" + std::to_string(j) + "]");
  }
  return out;
}

struct ConvertCommand {
  std::string in, out, obs_keys, action_features, domain, label;
  bool json = false;

  void Register(CLI::App& demos) {
    CLI::App* cmd = demos.add_subcommand(
        "convert",
        "Convert demonstrations or a state set between CSV and robomimic's HDF5 layout (by "
        "extension: .csv, .h5/.hdf5; either direction)");
    cmd->add_option("IN", in,
                    "input file: demonstrations (a CSV with an 'episode' column, or an "
                    "HDF5 file with data/demo_<i>) or a state set")
        ->required();
    cmd->add_option("OUT", out, "output file (.csv, .h5 or .hdf5)")->required();
    cmd->add_option("--obs-keys", obs_keys,
                    "comma-separated observation keys or columns to keep, in this order (an HDF5 "
                    "obs key of shape (T, k) is the columns <key>[0] .. <key>[k-1]; default: all)");
    cmd->add_option("--action-features", action_features,
                    "comma-separated action columns (CSV demonstrations: which columns are "
                    "actions; HDF5: which to keep; default: the --domain's, else all of HDF5)");
    AddDomainOption(cmd, &domain,
                    "CSV demonstrations: take the action columns (and, without --obs-keys, the "
                    "observation columns) from this domain");
    cmd->add_option("--label", label,
                    "the state set: its label in an HDF5 input (safety/<label>) or output "
                    "(default: the input file's stem)");
    cmd->add_flag("--json", json, "print what was converted as JSON");
    cmd->callback([this] { Run(); });
  }

  void Run() {
    for (const std::string* path : {&in, &out}) {
      std::string ext = std::filesystem::path(*path).extension().string();
      std::transform(ext.begin(), ext.end(), ext.begin(),
                     [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
      SECURE_CHECK(ext == ".csv" || data::IsHdf5Path(*path),
                   "demos convert: '" << *path << "': the extension says neither CSV (.csv) nor "
                                      << "HDF5 (.h5, .hdf5)");
    }
    std::vector<std::string> obs = data::SplitList(obs_keys);
    std::vector<std::string> actions = data::SplitList(action_features);
    if (!domain.empty() && (actions.empty() || obs.empty())) {
      const auto d = experiments::DomainRegistry::Global().Make(domain);
      const auto env = d->MakeEnvironment();
      if (actions.empty()) actions = env->ActionFeatures();
      if (obs.empty()) obs = env->ObservationFeatures();
    }

    std::optional<data::TrajectorySet> demos;
    std::vector<data::StateSet> sets;
    std::vector<std::string> labels;
    if (data::IsHdf5Path(in)) {
      const data::Hdf5Contents c = data::InspectHdf5(in);
      if (c.has_demonstrations && label.empty()) demos = data::ReadTrajectories(in, obs, actions);
      // HDF5 to HDF5 keeps every state set; to CSV, one (the labelled, the only) unless the
      // demonstrations are converted.
      std::vector<std::string> wanted;
      if (!label.empty()) {
        wanted = {label};
      } else if (data::IsHdf5Path(out)) {
        wanted = c.state_sets;
      } else if (!demos) {
        SECURE_CHECK(c.state_sets.size() == 1,
                     "demos convert: " << in << " holds " << c.state_sets.size() << " state sets ("
                                       << Join(c.state_sets) << "); choose one with --label");
        wanted = c.state_sets;
      }
      for (const std::string& l : wanted) {
        SECURE_CHECK(std::find(c.state_sets.begin(), c.state_sets.end(), l) != c.state_sets.end(),
                     "demos convert: " << in << " has no state set 'safety/" << l << "' (its sets: "
                                       << (c.state_sets.empty() ? "none" : Join(c.state_sets))
                                       << ")");
        sets.push_back(data::ReadStateSet(in, obs, l));
        labels.push_back(l);
      }
    } else {
      const data::NumericTable header = data::ReadCsv(in);
      const std::vector<std::string>& columns = header.columns;
      const bool is_demos = std::find(columns.begin(), columns.end(), "episode") != columns.end();
      obs = ExpandKeys(columns, obs);
      if (is_demos) {
        SECURE_CHECK(!actions.empty(),
                     "demos convert: " << in << " holds demonstrations (column 'episode'): name "
                                       << "the action columns with --action-features or --domain");
        if (obs.empty()) {
          for (const std::string& c : columns) {
            if (c != "episode" && c != "step" &&
                std::find(actions.begin(), actions.end(), c) == actions.end())
              obs.push_back(c);
          }
        }
        demos = data::ReadTrajectories(in, obs, actions);
      } else {
        sets.push_back(data::ReadStateSet(in, obs));
        labels.push_back(label.empty() ? std::filesystem::path(in).stem().string() : label);
      }
    }

    nlohmann::json sets_json = nlohmann::json::object();
    if (data::IsHdf5Path(out)) {
      std::vector<data::LabelledStateSet> labelled;
      for (std::size_t k = 0; k < sets.size(); ++k) labelled.push_back({labels[k], &sets[k]});
      data::WriteHdf5(out, demos ? &*demos : nullptr, labelled);
    } else if (demos) {
      data::WriteTrajectories(out, *demos);
      sets.clear();
    } else {
      data::WriteStateSet(out, sets.front());
    }
    for (std::size_t k = 0; k < sets.size(); ++k) sets_json[labels[k]] = sets[k].size();
    if (json) {
      nlohmann::json r = {
          {"command", "demos convert"}, {"in", in}, {"out", out}, {"state_sets", sets_json}};
      if (demos) {
        r["demonstrations"] = demos->num_episodes();
        r["steps"] = demos->num_steps();
        r["observation_features"] = demos->state_features;
        r["action_features"] = demos->action_features;
      } else {
        r["observation_features"] = sets.front().features;
      }
      PrintJson(r);
      return;
    }
    std::cout << "converted " << in << " -> " << out << ":";
    if (demos) {
      std::cout << " " << demos->num_episodes() << " demonstrations, " << demos->num_steps()
                << " steps, " << demos->state_features.size() << " observation and "
                << demos->action_features.size() << " action columns";
    }
    for (std::size_t k = 0; k < sets.size(); ++k) {
      std::cout << (demos || k > 0 ? ";" : "") << " state set '" << labels[k]
                << "': " << sets[k].size() << " states, " << sets[k].dim() << " columns";
    }
    std::cout << "\n";
  }
};

}  // namespace

void RegisterConvertCommand(CLI::App& demos) {
  static ConvertCommand command;
  command.Register(demos);
}

}  // namespace secure::cli
