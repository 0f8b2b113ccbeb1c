#include "secure/dynamics/transitions.h"

#include <fstream>
#include <set>
#include <string>

#include "secure/common/error.h"
#include "secure/common/excerpt.h"
#include "secure/common/strings.h"

namespace secure::dynamics {
namespace {

// The header row of a CSV file (names split at commas, surrounding spaces and \r removed).
std::vector<std::string> CsvHeader(const std::string& path) {
  std::ifstream in(path);
  SECURE_CHECK(in.good(), path << ": cannot open the transitions file");
  std::string line;
  std::getline(in, line);
  if (!line.empty() && line.back() == '\r') line.pop_back();
  std::vector<std::string> names;
  std::string::size_type start = 0;
  while (true) {
    const auto comma = line.find(',', start);
    std::string name = line.substr(start, comma == std::string::npos ? std::string::npos
                                                                      : comma - start);
    const auto b = name.find_first_not_of(' '), e = name.find_last_not_of(' ');
    names.push_back(b == std::string::npos ? std::string() : name.substr(b, e - b + 1));
    if (comma == std::string::npos) break;
    start = comma + 1;
  }
  return names;
}

}  // namespace

Transitions FromTrajectories(const data::TrajectorySet& demos) {
  Transitions t;
  t.source = demos.source;
  t.state_features = demos.state_features;
  t.action_features = demos.action_features;
  long n = 0;
  for (long e = 0; e < demos.num_episodes(); ++e)
    n += demos.episode_begin[e + 1] - demos.episode_begin[e] - 1;
  t.states.resize(t.state_dim(), n);
  t.actions.resize(t.action_dim(), n);
  t.next_states.resize(t.state_dim(), n);
  long c = 0;
  const bool csv = !data::IsHdf5Path(demos.source);
  for (long e = 0; e < demos.num_episodes(); ++e) {
    t.run_begin.push_back(c);
    for (long j = demos.episode_begin[e]; j + 1 < demos.episode_begin[e + 1]; ++j, ++c) {
      t.states.col(c) = demos.states.col(j);
      t.actions.col(c) = demos.actions.col(j);
      t.next_states.col(c) = demos.states.col(j + 1);
      t.lines.push_back(csv ? j + 2 : j);  // CSV: header is line 1
    }
    if (t.run_begin.back() == c) t.run_begin.pop_back();  // a one-step episode: no transition
  }
  t.run_begin.push_back(c);
  return t;
}

Transitions ReadTransitions(const std::string& path, const std::vector<std::string>& state_features,
                            const std::vector<std::string>& action_features) {
  SECURE_CHECK(!state_features.empty(), path << ": no state features given");
  SECURE_CHECK(!action_features.empty(), path << ": no action features given");
  Transitions t;
  if (data::IsHdf5Path(path)) {
    t = FromTrajectories(data::ReadTrajectories(path, state_features, action_features));
  } else {
    const std::vector<std::string> header = CsvHeader(path);
    const std::set<std::string> names(header.begin(), header.end());
    bool triples = true;
    for (const std::string& f : state_features) triples = triples && names.count(kNextPrefix + f);
    if (triples) {
      std::vector<std::string> select = state_features;
      select.insert(select.end(), action_features.begin(), action_features.end());
      for (const std::string& f : state_features) select.push_back(kNextPrefix + f);
      const data::NumericTable table = data::ReadCsv(path, select);
      const int d = static_cast<int>(state_features.size());
      const int a = static_cast<int>(action_features.size());
      t.source = path;
      t.state_features = state_features;
      t.action_features = action_features;
      t.states = table.values.topRows(d).cast<float>();
      t.actions = table.values.middleRows(d, a).cast<float>();
      t.next_states = table.values.bottomRows(d).cast<float>();
      t.lines = table.lines;
    } else {
      SECURE_CHECK(names.count("episode") > 0,
                   path << ": transitions need either next_<feature> columns for every state "
                           "feature (missing e.g. '"
                        << kNextPrefix << state_features.front()
                        << "') or an episode column (trajectories); the header has "
                        << Excerpt(Join(header)));
      t = FromTrajectories(data::ReadTrajectories(path, state_features, action_features));
    }
  }
  t.source = path;
  // Float overflow of a finite double (e.g. 1e300) is the one non-finite value the readers pass.
  for (const Eigen::MatrixXf* m : {&t.states, &t.actions, &t.next_states})
    for (long c = 0; c < t.size(); ++c)
      SECURE_CHECK(m->col(c).allFinite(), path << ":" << t.lines[c]
                                               << ": a value outside float range (|x| > 3.4e38)");
  SECURE_CHECK(t.size() > 0, path << ": no transitions (trajectories need episodes of at least "
                                     "two steps)");
  return t;
}

void Append(const Transitions& more, Transitions* all) {
  if (all->size() == 0 && all->state_features.empty()) {
    *all = more;
    return;
  }
  SECURE_CHECK(more.state_features == all->state_features &&
                   more.action_features == all->action_features,
               more.source << ": features (" << Join(more.state_features) << "; "
                           << Join(more.action_features) << ") differ from " << all->source << "'s ("
                           << Join(all->state_features) << "; " << Join(all->action_features)
                           << ")");
  const long n = all->size(), m = more.size();
  auto grow = [&](Eigen::MatrixXf& a, const Eigen::MatrixXf& b) {
    Eigen::MatrixXf c(a.rows(), n + m);
    c.leftCols(n) = a;
    c.rightCols(m) = b;
    a.swap(c);
  };
  grow(all->states, more.states);
  grow(all->actions, more.actions);
  grow(all->next_states, more.next_states);
  all->lines.insert(all->lines.end(), more.lines.begin(), more.lines.end());
  if (!all->run_begin.empty() && !more.run_begin.empty()) {
    all->run_begin.pop_back();
    for (long b : more.run_begin) all->run_begin.push_back(b + n);
  } else {
    all->run_begin.clear();
  }
  all->source += "+" + more.source;
}

void WriteTransitions(const std::string& path, const Transitions& t) {
  std::vector<std::string> columns = t.state_features;
  columns.insert(columns.end(), t.action_features.begin(), t.action_features.end());
  for (const std::string& f : t.state_features) columns.push_back(kNextPrefix + f);
  Eigen::MatrixXd values(columns.size(), t.size());
  values << t.states.cast<double>(), t.actions.cast<double>(), t.next_states.cast<double>();
  data::WriteCsv(path, columns, values);
}

}  // namespace secure::dynamics
