// Writing demonstrations and labelled state sets in robomimic's HDF5 layout (see data.h and
// docs/FILE_FORMATS.md): WriteHdf5, IsValidationDemo (the mask/train, mask/valid split),
// IsHdf5Path. The HDF5 C API stays in hdf5_*.cc: no public header includes hdf5.h.
//
// Files are written to memory, then to disk by WriteFileAtomically: writes share the CSV files'
// path handling (symlinks, atomic replacement) and HDF5 never locks a file.

#include <hdf5.h>

#include <unistd.h>

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <limits>
#include <map>
#include <mutex>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include <Eigen/Core>

#include "secure/common/atomic_file.h"
#include "secure/common/input_limits.h"
#include "secure/common/error.h"
#include "secure/common/excerpt.h"
#include "secure/common/filesystem.h"
#include "secure/common/strings.h"
#include "secure/data/data.h"
#include "secure/data/internal/hdf5_handle.h"
#include "secure/data/internal/hdf5_mutex.h"

namespace secure::data {
namespace {

using hdf5::Handle;
using hdf5::Hdf5Reason;
using hdf5::QuietHdf5;

constexpr const char* kEnvArgs =
    "{\"env_name\": \"secure\", \"type\": 2, \"env_kwargs\": {}}";  // robomimic EnvType.GYM_TYPE


class Writer {
 public:
  explicit Writer(std::string path) : path_(std::move(path)) {
    Handle fapl(H5Pcreate(H5P_FILE_ACCESS), H5Pclose);
    SECURE_CHECK(fapl.ok() && H5Pset_fapl_core(fapl.get(), 1 << 20, 0) >= 0,
                 "cannot write '" << path_ << "': HDF5 setup failed" << Hdf5Reason());
    // The name is only the in-memory file's: nothing is written to disk until Finish().
    file_ = Handle(H5Fcreate(path_.c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, fapl.get()), H5Fclose);
    SECURE_CHECK(file_.ok(),
                 "cannot write '" << path_ << "': HDF5 could not create the file" << Hdf5Reason());
  }

  hid_t file() const { return file_.get(); }

  // A group that keeps its links' creation order (so keys read back in the order written) and
  // no time stamps (so that the same data give the same bytes).
  Handle Group(hid_t loc, const std::string& name) {
    Handle gcpl(H5Pcreate(H5P_GROUP_CREATE), H5Pclose);
    H5Pset_link_creation_order(gcpl.get(), H5P_CRT_ORDER_TRACKED | H5P_CRT_ORDER_INDEXED);
    H5Pset_obj_track_times(gcpl.get(), 0);
    Handle group(H5Gcreate2(loc, name.c_str(), H5P_DEFAULT, gcpl.get(), H5P_DEFAULT), H5Gclose);
    Check(group.ok(), name);
    return group;
  }

  // A (rows,) or (rows, cols) dataset of `file_type` from row-major `values` of `mem_type`.
  void Dataset(hid_t loc, const std::string& name, hid_t file_type, hid_t mem_type,
               const void* values, hsize_t rows, hsize_t cols, int rank) {
    const hsize_t dims[2] = {rows, cols};
    Handle space(H5Screate_simple(rank, dims, nullptr), H5Sclose);
    Handle dcpl(H5Pcreate(H5P_DATASET_CREATE), H5Pclose);
    H5Pset_obj_track_times(dcpl.get(), 0);
    Handle dataset(
        H5Dcreate2(loc, name.c_str(), file_type, space.get(), H5P_DEFAULT, dcpl.get(), H5P_DEFAULT),
        H5Dclose);
    Check(dataset.ok() &&
              H5Dwrite(dataset.get(), mem_type, H5S_ALL, H5S_ALL, H5P_DEFAULT, values) >= 0,
          name);
  }

  // Rows [first, first + count) of `m` (features x steps), columns [begin, end), as a
  // (steps, count) float64 dataset.
  void Matrix(hid_t loc, const std::string& name, const Eigen::MatrixXf& m, Eigen::Index first,
              Eigen::Index count, Eigen::Index begin, Eigen::Index end) {
    std::vector<double> values;
    values.reserve(static_cast<std::size_t>(count * (end - begin)));
    for (Eigen::Index t = begin; t < end; ++t)
      for (Eigen::Index j = first; j < first + count; ++j) values.push_back(m(j, t));
    Dataset(loc, name, H5T_IEEE_F64LE, H5T_NATIVE_DOUBLE, values.data(), hsize_t(end - begin),
            hsize_t(count), 2);
  }

  // Columns `steps` (in this order) of rows [first, first + count) of `m` (features x steps), as
  // a (steps.size(), count) float64 dataset.
  void Matrix(hid_t loc, const std::string& name, const Eigen::MatrixXf& m, Eigen::Index first,
              Eigen::Index count, const std::vector<Eigen::Index>& steps) {
    std::vector<double> values;
    values.reserve(static_cast<std::size_t>(count) * steps.size());
    for (const Eigen::Index t : steps)
      for (Eigen::Index j = first; j < first + count; ++j) values.push_back(m(j, t));
    Dataset(loc, name, H5T_IEEE_F64LE, H5T_NATIVE_DOUBLE, values.data(), hsize_t(steps.size()),
            hsize_t(count), 2);
  }

  // A (n,) dataset of fixed-length byte strings, null-padded, as h5py writes
  // np.array(strings, dtype="S") (robomimic's filter keys); its width is the longest string's
  // (1 when there is none, as numpy's).
  void Strings(hid_t loc, const std::string& name, const std::vector<std::string>& strings) {
    std::size_t width = 1;
    for (const std::string& text : strings) width = std::max(width, text.size());
    std::string values(width * strings.size() + 1, '\0');  // + 1: never a null pointer
    for (std::size_t i = 0; i < strings.size(); ++i)
      std::copy(strings[i].begin(), strings[i].end(), values.begin() + long(i * width));
    Handle type(H5Tcopy(H5T_C_S1), H5Tclose);
    H5Tset_size(type.get(), width);
    H5Tset_strpad(type.get(), H5T_STR_NULLPAD);
    Dataset(loc, name, type.get(), type.get(), values.data(), hsize_t(strings.size()), 1, 1);
  }

  void IntAttribute(hid_t loc, const char* name, long long value) {
    Handle space(H5Screate(H5S_SCALAR), H5Sclose);
    Handle attr(H5Acreate2(loc, name, H5T_STD_I64LE, space.get(), H5P_DEFAULT, H5P_DEFAULT),
                H5Aclose);
    Check(attr.ok() && H5Awrite(attr.get(), H5T_NATIVE_LLONG, &value) >= 0, name);
  }

  // A variable-length UTF-8 string, as h5py writes a Python str.
  void StringAttribute(hid_t loc, const char* name, const std::string& value) {
    Handle type(H5Tcopy(H5T_C_S1), H5Tclose);
    H5Tset_size(type.get(), H5T_VARIABLE);
    H5Tset_cset(type.get(), H5T_CSET_UTF8);
    Handle space(H5Screate(H5S_SCALAR), H5Sclose);
    Handle attr(H5Acreate2(loc, name, type.get(), space.get(), H5P_DEFAULT, H5P_DEFAULT), H5Aclose);
    const char* text = value.c_str();
    Check(attr.ok() && H5Awrite(attr.get(), type.get(), &text) >= 0, name);
  }

  // Writes the in-memory file to path (atomically).
  void Finish() {
    Check(H5Fflush(file_.get(), H5F_SCOPE_GLOBAL) >= 0, "flush");
    const ssize_t size = H5Fget_file_image(file_.get(), nullptr, 0);
    Check(size > 0, "file image");
    std::string image(static_cast<std::size_t>(size), '\0');
    Check(H5Fget_file_image(file_.get(), image.data(), image.size()) == size, "file image");
    file_ = Handle();
    WriteFileAtomically(path_, image);
  }

 private:
  void Check(bool ok, const std::string& what) const {
    SECURE_CHECK(ok, "cannot write '" << path_ << "': HDF5 failed on " << what << Hdf5Reason());
  }

  QuietHdf5 quiet_;
  std::string path_;
  Handle file_;
};

// Groups feature names into obs keys: a run "k[0]", "k[1]", ..., "k[n-1]" (n >= 2) becomes key
// k with n columns; any other name is a key of its own with one column. Each key is a
// (first row, count) range of the features.
struct KeyRange {
  std::string name;
  Eigen::Index first = 0, count = 0;
};

std::vector<KeyRange> GroupKeys(const std::string& path, const std::vector<std::string>& features) {
  std::vector<KeyRange> keys;
  const auto base_of = [](const std::string& name, long index) -> std::string {
    const std::string suffix = "[" + std::to_string(index) + "]";
    if (name.size() <= suffix.size() ||
        name.compare(name.size() - suffix.size(), suffix.size(), suffix) != 0)
      return {};
    return name.substr(0, name.size() - suffix.size());
  };
  for (std::size_t i = 0; i < features.size();) {
    const std::string base = base_of(features[i], 0);
    std::size_t n = 1;
    if (!base.empty()) {
      while (i + n < features.size() && base_of(features[i + n], long(n)) == base) ++n;
    }
    if (n >= 2) {
      keys.push_back({base, Eigen::Index(i), Eigen::Index(n)});
    } else {
      keys.push_back({features[i], Eigen::Index(i), 1});
    }
    i += n;
  }
  for (std::size_t k = 0; k < keys.size(); ++k) {
    const std::string& name = keys[k].name;
    SECURE_CHECK(!name.empty() && name.find('/') == std::string::npos && name != ".",
                 "cannot write '" << path << "': feature '" << name
                                  << "' cannot be an HDF5 name (empty, '.' or contains '/')");
    for (std::size_t i = 0; i < k; ++i) {
      SECURE_CHECK(keys[i].name != name, "cannot write '" << path << "': obs key '" << name
                                                          << "' would be written twice (features "
                                                          << Excerpt(Join(features), 400) << ")");
    }
  }
  return keys;
}

void CheckFinite(const std::string& path, const Eigen::MatrixXf& m,
                 const std::vector<std::string>& names) {
  for (Eigen::Index t = 0; t < m.cols(); ++t)
    for (Eigen::Index j = 0; j < m.rows(); ++j)
      SECURE_CHECK(std::isfinite(m(j, t)), "cannot write '"
                                               << path << "': value " << m(j, t) << " of feature '"
                                               << names[static_cast<std::size_t>(j)] << "', row "
                                               << t << " (0-based) is not finite");
}

void WriteObs(Writer& w, hid_t group, const std::vector<KeyRange>& keys, const Eigen::MatrixXf& m,
              Eigen::Index begin, Eigen::Index end) {
  const Handle obs = w.Group(group, "obs");
  for (const KeyRange& k : keys) w.Matrix(obs.get(), k.name, m, k.first, k.count, begin, end);
}

// next_obs/<key>: row t is the observation of step t + 1; the last step's is its own (the
// observation after the last action is not recorded; dones marks the step).
void WriteNextObs(Writer& w, hid_t group, const std::vector<KeyRange>& keys,
                  const Eigen::MatrixXf& m, Eigen::Index begin, Eigen::Index end) {
  std::vector<Eigen::Index> next;
  for (Eigen::Index t = begin; t < end; ++t) next.push_back(std::min(t + 1, end - 1));
  const Handle obs = w.Group(group, "next_obs");
  for (const KeyRange& k : keys) w.Matrix(obs.get(), k.name, m, k.first, k.count, next);
}


}  // namespace

bool IsValidationDemo(long index, long demos) {
  if (demos < 2 || index < 0 || index >= demos) return false;
  return index % 10 == 9 || (demos < 10 && index == demos - 1);
}

namespace {

void WriteDemos(Writer& w, const std::string& path, const TrajectorySet& set) {
  const auto state_dim = static_cast<Eigen::Index>(set.state_features.size());
  const auto action_dim = static_cast<Eigen::Index>(set.action_features.size());
  const Eigen::Index steps = set.states.cols();
  SECURE_CHECK(state_dim > 0, "cannot write '" << path << "': no state features");
  SECURE_CHECK(action_dim > 0,
               "cannot write '" << path << "': no action features (robomimic demos hold actions)");
  SECURE_CHECK(set.states.rows() == state_dim && set.actions.rows() == action_dim &&
                   set.actions.cols() == steps,
               "cannot write '" << path << "': the states (" << set.states.rows() << " x " << steps
                                << ") and actions (" << set.actions.rows() << " x "
                                << set.actions.cols() << ") disagree with the " << state_dim
                                << " state and " << action_dim << " action feature names");
  SECURE_CHECK(steps > 0, "cannot write '" << path << "': 0 steps (would not read back)");
  const std::vector<long>& begin = set.episode_begin;
  SECURE_CHECK(begin.size() >= 2 && begin.front() == 0 && begin.back() == steps,
               "cannot write '" << path << "': episode_begin must start at 0 and end at " << steps);
  for (std::size_t k = 0; k + 1 < begin.size(); ++k)
    SECURE_CHECK(begin[k] < begin[k + 1],
                 "cannot write '" << path << "': episode " << k << " is empty or reversed");
  for (const std::string& name : set.action_features)
    SECURE_CHECK(!name.empty() && name.find(',') == std::string::npos,
                 "cannot write '" << path << "': action feature '" << name
                                  << "' is empty or contains a comma");
  CheckFinite(path, set.states, set.state_features);
  CheckFinite(path, set.actions, set.action_features);
  const std::vector<KeyRange> keys = GroupKeys(path, set.state_features);

  const Handle data = w.Group(w.file(), "data");
  w.IntAttribute(data.get(), "total", steps);
  w.StringAttribute(data.get(), "env_args", kEnvArgs);
  w.StringAttribute(data.get(), "action_features", Join(set.action_features, ","));
  for (std::size_t k = 0; k + 1 < begin.size(); ++k) {
    const Handle demo = w.Group(data.get(), "demo_" + std::to_string(k));
    const long b = begin[k], e = begin[k + 1], n = e - b;
    w.IntAttribute(demo.get(), "num_samples", n);
    WriteObs(w, demo.get(), keys, set.states, b, e);
    WriteNextObs(w, demo.get(), keys, set.states, b, e);
    w.Matrix(demo.get(), "actions", set.actions, 0, action_dim, b, e);
    std::vector<long long> dones(static_cast<std::size_t>(n), 0);
    dones.back() = 1;
    w.Dataset(demo.get(), "dones", H5T_STD_I64LE, H5T_NATIVE_LLONG, dones.data(), hsize_t(n), 1, 1);
    const std::vector<double> rewards(static_cast<std::size_t>(n), 0.0);
    w.Dataset(demo.get(), "rewards", H5T_IEEE_F64LE, H5T_NATIVE_DOUBLE, rewards.data(), hsize_t(n),
              1, 1);
    w.Matrix(demo.get(), "states", set.states, 0, state_dim, b, e);
  }
  // robomimic's filter keys (mask/train, mask/valid: demo names), see IsValidationDemo.
  std::vector<std::string> train, valid;
  const long demos = set.num_episodes();
  for (long k = 0; k < demos; ++k)
    (IsValidationDemo(k, demos) ? valid : train).push_back("demo_" + std::to_string(k));
  const Handle mask = w.Group(w.file(), "mask");
  w.Strings(mask.get(), "train", train);
  w.Strings(mask.get(), "valid", valid);
}

void WriteSets(Writer& w, const std::string& path, const std::vector<LabelledStateSet>& sets) {
  if (sets.empty()) return;
  const Handle safety = w.Group(w.file(), "safety");
  for (std::size_t s = 0; s < sets.size(); ++s) {
    const std::string& label = sets[s].label;
    const StateSet& set = *sets[s].set;
    SECURE_CHECK(!label.empty() && label.find('/') == std::string::npos && label != ".",
                 "cannot write '" << path << "': state set label '" << label
                                  << "' cannot be an HDF5 name (empty, '.' or contains '/')");
    for (std::size_t i = 0; i < s; ++i)
      SECURE_CHECK(sets[i].label != label,
                   "cannot write '" << path << "': two state sets labelled '" << label << "'");
    SECURE_CHECK(set.states.rows() == set.dim() && set.dim() > 0,
                 "cannot write '" << path << "': the states have " << set.states.rows()
                                  << " rows but " << set.dim() << " feature names");
    SECURE_CHECK(set.size() > 0, "cannot write '" << path << "': 0 states (would not read back)");
    CheckFinite(path, set.states, set.features);
    const Handle group = w.Group(safety.get(), label);
    w.IntAttribute(group.get(), "num_samples", set.size());
    WriteObs(w, group.get(), GroupKeys(path, set.features), set.states, 0, set.size());
  }
}

}  // namespace

bool IsHdf5Path(const std::string& path) {
  std::string ext = std::filesystem::path(path).extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return ext == ".h5" || ext == ".hdf5";
}

void WriteHdf5(const std::string& path, const TrajectorySet* demos,
               const std::vector<LabelledStateSet>& sets) {
  SECURE_CHECK(demos != nullptr || !sets.empty(),
               "cannot write '" << path << "': no demonstrations and no state sets");
  // One libhdf5 call sequence at a time, and never while a reader forks (hdf5_guard.cc).
  const std::lock_guard<std::mutex> lock(hdf5::Hdf5LibraryMutex());
  Writer w(path);
  if (demos != nullptr) WriteDemos(w, path, *demos);
  WriteSets(w, path, sets);
  w.Finish();
}

}  // namespace secure::data
