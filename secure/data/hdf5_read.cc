// Reading demonstrations and state sets in robomimic's HDF5 layout (see data.h and
// docs/FILE_FORMATS.md), in this process: internal::InspectHdf5InProcess,
// ReadHdf5TrajectoriesInProcess, ReadHdf5StateSetInProcess. The public readers run these in a
// child process (hdf5_guard.cc: libhdf5 itself crashes on some malformed files). The HDF5 C API
// stays in hdf5_*.cc: no public header includes hdf5.h.
//
// Files are read from memory (the bytes from ReadFile, opened through the core driver's file
// image): reads share the CSV files' path handling (FIFOs, symlinks) and HDF5 never locks a file.

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

namespace secure::data {
namespace {

using hdf5::Handle;
using hdf5::Hdf5Reason;
using hdf5::QuietHdf5;
using hdf5::IsIeeeFloat;
using hdf5::TypeName;

// Formats a value read from a file (shortest round trip).
std::string Shown(double value) {
  if (std::isnan(value)) return "nan";
  if (std::isinf(value)) return value > 0 ? "inf" : "-inf";
  char buffer[32];
  const auto result = std::to_chars(buffer, buffer + sizeof(buffer), value);
  return std::string(buffer, result.ptr);
}


// The column names of an obs key with `cols` columns: "<key>" or "<key>[0]", ..., "<key>[k-1]".
std::string ColumnName(const std::string& key, long cols, long j) {
  return cols == 1 ? key : key + "[" + std::to_string(j) + "]";
}

// A (rows x cols) dataset read as row-major doubles.
struct Table {
  long rows = 0, cols = 0;
  std::vector<double> values;
};

// An obs key (or the actions) of a group: its dataset's name and width.
struct Key {
  std::string name;
  long cols = 0;
  std::string problem;  // why the dataset cannot be read as features (e.g. an image), or ""
};

// A selected column: key index and column within the key.
struct Column {
  std::size_t key = 0;
  long col = 0;
};

class Reader {
 public:
  explicit Reader(std::string path) : path_(std::move(path)) {
    image_ = ReadFile(path_);  // a regular file within the input limit (input_limits.h)
    SECURE_CHECK(HasSignature(), path_ << ": not an HDF5 file (no HDF5 signature)");
    Handle fapl(H5Pcreate(H5P_FILE_ACCESS), H5Pclose);
    SECURE_CHECK(fapl.ok() && H5Pset_fapl_core(fapl.get(), 1 << 16, 0) >= 0 &&
                     H5Pset_file_image(fapl.get(), image_.data(), image_.size()) >= 0,
                 path_ << ": cannot set up the HDF5 reader" << Hdf5Reason());
    // The core driver refuses an image whose name is an existing file: the name must be one
    // no file has (it names nothing on disk; messages name path_).
    static std::atomic<unsigned long> counter{0};
    const std::string name = "/nonexistent/secure-hdf5-image-" + std::to_string(::getpid()) + "-" +
                             std::to_string(counter++);
    file_ = Handle(H5Fopen(name.c_str(), H5F_ACC_RDONLY, fapl.get()), H5Fclose);
    SECURE_CHECK(file_.ok(),
                 path_ << ": cannot open as HDF5 (corrupt or truncated file?)" << Hdf5Reason());
  }

  const std::string& path() const { return path_; }
  hid_t file() const { return file_.get(); }

  // The kind of the link `name` in `loc`: H5I_GROUP, H5I_DATASET, or H5I_BADID if it does not
  // exist (or is something else, e.g. a dangling link).
  H5I_type_t KindOf(hid_t loc, const std::string& name) const {
    if (H5Lexists(loc, name.c_str(), H5P_DEFAULT) <= 0) return H5I_BADID;
    Handle object(H5Oopen(loc, name.c_str(), H5P_DEFAULT), H5Oclose);
    if (!object.ok()) return H5I_BADID;
    return H5Iget_type(object.get());
  }

  // Opens group `name` in `loc`; `where` is its full path for messages.
  Handle OpenGroup(hid_t loc, const std::string& name, const std::string& where,
                   const std::string& what) const {
    const H5I_type_t kind = KindOf(loc, name);
    SECURE_CHECK(kind != H5I_BADID, path_ << ": no group '" << where << "' (" << what << ")");
    SECURE_CHECK(kind == H5I_GROUP, path_ << ": " << where << " is not a group (" << what << ")");
    Handle group(H5Gopen2(loc, name.c_str(), H5P_DEFAULT), H5Gclose);
    SECURE_CHECK(group.ok(), path_ << ": " << where << ": cannot open the group" << Hdf5Reason());
    return group;
  }

  // The names of the links in `group`, in creation order if the file tracks it (our files, so
  // that keys read back in the order they were written), else in name order (h5py's default).
  std::vector<std::string> Children(hid_t group, const std::string& where) const {
    H5G_info_t info;
    SECURE_CHECK(H5Gget_info(group, &info) >= 0,
                 path_ << ": " << where << ": cannot list the group" << Hdf5Reason());
    H5_index_t index = H5_INDEX_NAME;
    Handle gcpl(H5Gget_create_plist(group), H5Pclose);
    unsigned flags = 0;
    if (gcpl.ok() && H5Pget_link_creation_order(gcpl.get(), &flags) >= 0 &&
        (flags & H5P_CRT_ORDER_TRACKED) != 0) {
      index = H5_INDEX_CRT_ORDER;
    }
    std::vector<std::string> names;
    for (hsize_t i = 0; i < info.nlinks; ++i) {
      const ssize_t size =
          H5Lget_name_by_idx(group, ".", index, H5_ITER_INC, i, nullptr, 0, H5P_DEFAULT);
      SECURE_CHECK(size >= 0, path_ << ": " << where << ": cannot read link " << i << Hdf5Reason());
      std::string name(static_cast<std::size_t>(size) + 1, '\0');
      H5Lget_name_by_idx(group, ".", index, H5_ITER_INC, i, name.data(), name.size(), H5P_DEFAULT);
      name.resize(static_cast<std::size_t>(size));
      names.push_back(std::move(name));
    }
    return names;
  }

  // Opens dataset `name` in `loc` and checks it is (T,) or (T, k) floating point; returns its
  // width k (1 for (T,)) and sets *rows.
  Handle OpenFloatDataset(hid_t loc, const std::string& name, const std::string& where, long* rows,
                          long* cols) const {
    const H5I_type_t kind = KindOf(loc, name);
    SECURE_CHECK(kind != H5I_BADID, path_ << ": no dataset '" << where << "'");
    SECURE_CHECK(
        kind == H5I_DATASET,
        path_ << ": " << where << " is a group, expected a dataset of shape (T,) or (T, k)");
    Handle dataset(H5Dopen2(loc, name.c_str(), H5P_DEFAULT), H5Dclose);
    SECURE_CHECK(dataset.ok(), path_ << ": " << where << ": cannot open" << Hdf5Reason());
    Handle type(H5Dget_type(dataset.get()), H5Tclose);
    const H5T_class_t type_class = type.ok() ? H5Tget_class(type.get()) : H5T_NO_CLASS;
    Handle space(H5Dget_space(dataset.get()), H5Sclose);
    const int rank = space.ok() ? H5Sget_simple_extent_ndims(space.get()) : -1;
    SECURE_CHECK(rank >= 0, path_ << ": " << where << ": cannot read the shape" << Hdf5Reason());
    hsize_t dims[H5S_MAX_RANK] = {};
    H5Sget_simple_extent_dims(space.get(), dims, nullptr);
    std::string shape = "(";
    for (int i = 0; i < rank; ++i) shape += (i > 0 ? ", " : "") + std::to_string(dims[i]);
    shape += rank == 1 ? ",)" : ")";
    // E.g. robomimic's images: "data type is uint8 (shape (T, 84, 84, 3)), expected ...".
    SECURE_CHECK(type_class == H5T_FLOAT, path_ << ": " << where << ": data type is "
                                                << TypeName(type.get(), type_class) << " (shape "
                                                << shape << "), expected float32 or float64");
    // A float type of another layout than IEEE binary32 / binary64 (a mutated file can declare
    // e.g. a 4-billion-byte float): libhdf5's conversion would allocate by its size.
    SECURE_CHECK(IsIeeeFloat(type.get()),
                 path_ << ": " << where << ": data type is a float of " << H5Tget_size(type.get())
                       << " bytes with precision " << H5Tget_precision(type.get())
                       << ", expected IEEE float32 or float64");
    SECURE_CHECK(rank == 1 || rank == 2, path_ << ": " << where << ": shape " << shape
                                               << " has rank " << rank
                                               << ", expected (T,) or (T, k)");
    const hsize_t width = rank == 2 ? dims[1] : 1;
    SECURE_CHECK(width >= 1, path_ << ": " << where << ": shape " << shape
                                   << " has no columns, expected (T,) or (T, k) with k >= 1");
    // The declared size, checked before anything is allocated for it (issue 34: a 10 KB file
    // can declare a chunked, never-written dataset of 2e9 rows): its values read as doubles,
    // with every dataset read before it, within the input limit (input_limits.h).
    const std::uint64_t limit = GetInputLimits().max_input_bytes;
    const std::uint64_t max_values = limit / sizeof(double);
    SECURE_CHECK(dims[0] <= max_values / width,
                 path_ << ": " << where << ": shape " << shape << " declares "
                       << static_cast<double>(dims[0]) * static_cast<double>(width) * 8.0
                       << " bytes (as doubles), over the input limit of " << limit
                       << " bytes (raise it with SECURE_MAX_INPUT_BYTES or --max-input-bytes)");
    // A chunked dataset's chunk is allocated whole by H5Dread, whatever the dataset's size: its
    // declared size is checked too (the HDF5 fuzzer found a file whose chunk made a small read
    // allocate 2.5 GB).
    Handle plist(H5Dget_create_plist(dataset.get()), H5Pclose);
    if (plist.ok() && H5Pget_layout(plist.get()) == H5D_CHUNKED) {
      hsize_t chunk[H5S_MAX_RANK] = {};
      const int chunk_rank = H5Pget_chunk(plist.get(), H5S_MAX_RANK, chunk);
      const std::size_t element = type.ok() ? H5Tget_size(type.get()) : 8;
      long double bytes = static_cast<long double>(std::max<std::size_t>(element, 8));
      for (int i = 0; i < chunk_rank; ++i) bytes *= static_cast<long double>(chunk[i]);
      SECURE_CHECK(chunk_rank >= 0 && bytes <= static_cast<long double>(limit),
                   path_ << ": " << where << ": its chunks declare "
                         << static_cast<double>(bytes) << " bytes each, over the input limit of "
                         << limit << " bytes (raise it with SECURE_MAX_INPUT_BYTES or "
                            "--max-input-bytes)");
    }
    // Contiguous data must lie within the file: libhdf5 sizes its read buffer by the declared
    // storage (the fuzzer found 4 GB declared for 80 bytes of data in a 10 KB file).
    if (plist.ok() && H5Pget_layout(plist.get()) == H5D_CONTIGUOUS) {
      const hsize_t storage = H5Dget_storage_size(dataset.get());
      const haddr_t offset = H5Dget_offset(dataset.get());
      SECURE_CHECK(storage <= image_.size() &&
                       (offset == HADDR_UNDEF || offset <= image_.size() - storage),
                   path_ << ": " << where << ": its data (" << storage << " bytes at offset "
                         << (offset == HADDR_UNDEF ? std::string("none") : std::to_string(offset))
                         << ") lie beyond the end of the " << image_.size()
                         << "-byte file (corrupt file?)");
    }
    *rows = static_cast<long>(dims[0]);
    *cols = static_cast<long>(width);
    return dataset;
  }

  // Reads a float dataset (see OpenFloatDataset) as doubles and checks every value is finite.
  Table ReadFloatDataset(hid_t loc, const std::string& name, const std::string& where) const {
    Table t;
    const Handle dataset = OpenFloatDataset(loc, name, where, &t.rows, &t.cols);
    // And all datasets read from this file together (many small declared datasets).
    const std::uint64_t limit = GetInputLimits().max_input_bytes;
    const std::uint64_t values = static_cast<std::uint64_t>(t.rows * t.cols);
    SECURE_CHECK(declared_values_ + values <= limit / sizeof(double),
                 path_ << ": " << where << ": " << values * sizeof(double) << " more bytes after "
                       << declared_values_ * sizeof(double)
                       << " of other datasets, over the input limit of " << limit
                       << " bytes (raise it with SECURE_MAX_INPUT_BYTES or --max-input-bytes)");
    declared_values_ += values;
    t.values.resize(static_cast<std::size_t>(t.rows * t.cols));
    if (!t.values.empty()) {
      SECURE_CHECK(
          H5Dread(dataset.get(), H5T_NATIVE_DOUBLE, H5S_ALL, H5S_ALL, H5P_DEFAULT,
                  t.values.data()) >= 0,
          path_ << ": " << where << ": cannot read the data (corrupt file?)" << Hdf5Reason());
    }
    for (long r = 0; r < t.rows; ++r) {
      for (long c = 0; c < t.cols; ++c) {
        const double v = t.values[static_cast<std::size_t>(r * t.cols + c)];
        SECURE_CHECK(std::isfinite(v), path_ << ": " << where << ": row " << r << ", column " << c
                                             << ": value " << Shown(v) << " is not finite");
        SECURE_CHECK(std::abs(v) <= std::numeric_limits<float>::max(),
                     path_ << ": " << where << ": row " << r << ", column " << c << ": value "
                           << Shown(v) << " is out of the float range");
      }
    }
    return t;
  }

  // The keys of `obs` (a group): each dataset's name and width, in file order. A key that is
  // no (T,) or (T, k) float dataset (e.g. robomimic's images, (T, H, W, C) uint8) is kept with
  // its problem, an error only if it is selected.
  std::vector<Key> Keys(hid_t obs, const std::string& where) const {
    std::vector<Key> keys;
    for (const std::string& name : Children(obs, where)) {
      long rows = 0, cols = 0;
      try {
        OpenFloatDataset(obs, name, where + "/" + name, &rows, &cols);
        keys.push_back({name, cols, ""});
      } catch (const Error& e) {
        keys.push_back({name, 0, e.what()});
      }
    }
    SECURE_CHECK(!keys.empty(), path_ << ": " << where << ": no observation keys");
    return keys;
  }

  // Resolves `select` (column names, or obs keys standing for all their columns; empty: every
  // column) against `keys` of group `where`. Sets *names to the selected column names.
  std::vector<Column> Resolve(const std::vector<Key>& keys, const std::vector<std::string>& select,
                              const std::string& where, std::vector<std::string>* names) const {
    std::map<std::string, Column> column_of;
    std::vector<std::string> all;
    for (std::size_t k = 0; k < keys.size(); ++k) {
      for (long j = 0; j < keys[k].cols; ++j) {
        all.push_back(ColumnName(keys[k].name, keys[k].cols, j));
        column_of.emplace(all.back(), Column{k, j});
      }
    }
    std::vector<Column> columns;
    names->clear();
    const auto usable = [&](const Key& k) {
      if (!k.problem.empty()) throw Error(k.problem);
    };
    const auto add = [&](const std::string& name, Column c) {
      SECURE_CHECK(std::find(names->begin(), names->end(), name) == names->end(),
                   path_ << ": " << where << ": column '" << Excerpt(name)
                         << "' is selected twice (selection: " << Excerpt(Join(select)) << ")");
      names->push_back(name);
      columns.push_back(c);
    };
    if (select.empty()) {
      std::vector<std::string> readable;
      for (const Key& k : keys)
        if (k.problem.empty()) readable.push_back(k.name);
      for (const Key& k : keys) {
        SECURE_CHECK(k.problem.empty(),
                     k.problem << "; no keys were selected, so every key is read: select the "
                               << "others by name ("
                               << (readable.empty() ? std::string("none is readable")
                                                    : Excerpt(Join(readable), 400))
                               << ")");
      }
      for (const std::string& name : all) add(name, column_of.at(name));
      return columns;
    }
    for (const std::string& name : select) {
      const auto it = column_of.find(name);
      if (it != column_of.end()) {
        add(name, it->second);
        continue;
      }
      const auto key =
          std::find_if(keys.begin(), keys.end(), [&](const Key& k) { return k.name == name; });
      SECURE_CHECK(key != keys.end(),
                   path_ << ": " << where << ": no key or column '" << Excerpt(name)
                         << "'; the keys are: " << Excerpt(DescribeKeys(keys), 400));
      usable(*key);
      const auto k = static_cast<std::size_t>(key - keys.begin());
      for (long j = 0; j < key->cols; ++j) add(ColumnName(key->name, key->cols, j), {k, j});
    }
    return columns;
  }

  // "x, vel (2 columns: vel[0], vel[1])".
  static std::string DescribeKeys(const std::vector<Key>& keys) {
    std::string out;
    for (const Key& k : keys) {
      if (!out.empty()) out += ", ";
      out += k.name;
      if (!k.problem.empty()) out += " (not (T,) or (T, k) float)";
      if (k.cols > 1) {
        out += " (" + std::to_string(k.cols) + " columns: " + ColumnName(k.name, k.cols, 0) +
               " .. " + ColumnName(k.name, k.cols, k.cols - 1) + ")";
      }
    }
    return out;
  }

  // Reads the columns `columns` of the datasets `keys` (all in group `loc`, path `where`) into
  // `out`, columns [first, first + T): all keys must have T rows (*rows; < 0: not known yet)
  // and the width recorded in `keys`.
  void ReadColumns(hid_t loc, const std::string& where, const std::vector<Key>& keys,
                   const std::vector<Column>& columns, std::string* rows_from, long* rows,
                   std::vector<std::vector<float>>* out) const {
    std::vector<bool> used(keys.size(), false);
    for (const Column& c : columns) used[c.key] = true;
    std::vector<Table> tables(keys.size());
    for (std::size_t k = 0; k < keys.size(); ++k) {
      if (!used[k]) continue;
      const std::string dataset = where + "/" + keys[k].name;
      SECURE_CHECK(KindOf(loc, keys[k].name) != H5I_BADID, path_ << ": " << where << ": no key '"
                                                                 << keys[k].name << "' (dataset "
                                                                 << dataset << ")");
      tables[k] = ReadFloatDataset(loc, keys[k].name, dataset);
      SECURE_CHECK(tables[k].cols == keys[k].cols,
                   path_ << ": " << dataset << ": " << tables[k].cols << " columns, but "
                         << keys[k].cols << " in the first group read");
      if (*rows < 0) {
        *rows = tables[k].rows;
        *rows_from = dataset;
      }
      SECURE_CHECK(tables[k].rows == *rows, path_ << ": " << dataset << ": " << tables[k].rows
                                                  << " rows, but " << *rows_from << " has " << *rows
                                                  << " (one row per step)");
    }
    out->resize(columns.size());
    for (std::size_t i = 0; i < columns.size(); ++i) {
      const Table& t = tables[columns[i].key];
      std::vector<float>& v = (*out)[i];
      v.resize(static_cast<std::size_t>(t.rows));
      for (long r = 0; r < t.rows; ++r)
        v[static_cast<std::size_t>(r)] =
            static_cast<float>(t.values[static_cast<std::size_t>(r * t.cols + columns[i].col)]);
    }
  }

  // An integer scalar attribute, if present.
  bool ReadIntAttribute(hid_t loc, const char* name, const std::string& where,
                        long long* value) const {
    if (H5Aexists(loc, name) <= 0) return false;
    Handle attr(H5Aopen(loc, name, H5P_DEFAULT), H5Aclose);
    Handle type(attr.ok() ? H5Aget_type(attr.get()) : -1, H5Tclose);
    const H5T_class_t c = type.ok() ? H5Tget_class(type.get()) : H5T_NO_CLASS;
    Handle space(attr.ok() ? H5Aget_space(attr.get()) : -1, H5Sclose);
    SECURE_CHECK((c == H5T_INTEGER || c == H5T_FLOAT) && space.ok() &&
                     H5Sget_simple_extent_npoints(space.get()) == 1 &&
                     H5Aread(attr.get(), H5T_NATIVE_LLONG, value) >= 0,
                 path_ << ": " << where << ": attribute '" << name << "' is not a single integer");
    return true;
  }

  // A string attribute (variable- or fixed-length), if present.
  bool ReadStringAttribute(hid_t loc, const char* name, const std::string& where,
                           std::string* value) const {
    if (H5Aexists(loc, name) <= 0) return false;
    Handle attr(H5Aopen(loc, name, H5P_DEFAULT), H5Aclose);
    Handle type(attr.ok() ? H5Aget_type(attr.get()) : -1, H5Tclose);
    SECURE_CHECK(type.ok() && H5Tget_class(type.get()) == H5T_STRING,
                 path_ << ": " << where << ": attribute '" << name << "' is not a string");
    Handle memtype(H5Tcopy(H5T_C_S1), H5Tclose);
    H5Tset_cset(memtype.get(), H5Tget_cset(type.get()));  // HDF5 converts no character sets
    if (H5Tis_variable_str(type.get()) > 0) {
      H5Tset_size(memtype.get(), H5T_VARIABLE);
      char* text = nullptr;
      SECURE_CHECK(H5Aread(attr.get(), memtype.get(), &text) >= 0,
                   path_ << ": " << where << ": cannot read attribute '" << name << "'");
      *value = text != nullptr ? text : "";
      H5free_memory(text);
    } else {
      const std::size_t size = H5Tget_size(type.get());
      H5Tset_size(memtype.get(), size);
      std::string text(size, '\0');
      SECURE_CHECK(H5Aread(attr.get(), memtype.get(), text.data()) >= 0,
                   path_ << ": " << where << ": cannot read attribute '" << name << "'");
      text.resize(std::min(text.find('\0'), text.size()));
      *value = text;
    }
    return true;
  }

 private:
  mutable std::uint64_t declared_values_ = 0;  // values of the datasets read so far
  bool HasSignature() const {
    static constexpr std::string_view kSignature("\x89HDF\r\n\x1a\n", 8);
    // The superblock is at 0 or, after a user block, at 512, 1024, 2048, ...
    for (std::size_t at = 0; at + kSignature.size() <= image_.size(); at = at == 0 ? 512 : 2 * at)
      if (std::string_view(image_).substr(at, kSignature.size()) == kSignature) return true;
    return false;
  }

  QuietHdf5 quiet_;
  std::string path_;
  std::string image_;
  Handle file_;
};

// The demo groups of data/: "demo_<i>" sorted by i (as robomimic does).
std::vector<std::string> DemoNames(const Reader& r, hid_t data) {
  std::vector<std::pair<long long, std::string>> demos;
  for (const std::string& name : r.Children(data, "data")) {
    long long index = -1;
    const std::string_view digits =
        std::string_view(name).substr(std::min<std::size_t>(5, name.size()));
    const auto [ptr, ec] = std::from_chars(digits.data(), digits.data() + digits.size(), index);
    SECURE_CHECK(name.rfind("demo_", 0) == 0 && !digits.empty() && ec == std::errc() &&
                     ptr == digits.data() + digits.size() && index >= 0,
                 r.path() << ": data/" << Excerpt(name)
                          << ": not a demo (expected groups demo_0, demo_1, ...)");
    demos.emplace_back(index, name);
  }
  SECURE_CHECK(!demos.empty(), r.path()
                                   << ": data: no demos (expected groups demo_0, demo_1, ...)");
  std::sort(demos.begin(), demos.end());
  std::vector<std::string> names;
  for (auto& d : demos) names.push_back(std::move(d.second));
  return names;
}

// The action column names of data/: the "action_features" attribute that our writer adds if it
// names `cols` columns, else "actions" / "actions[j]".
std::vector<Key> ActionKeys(const Reader& r, hid_t data, long cols,
                            std::vector<std::string>* names) {
  std::string text;
  names->clear();
  if (r.ReadStringAttribute(data, "action_features", "data", &text)) *names = SplitList(text);
  if (static_cast<long>(names->size()) != cols) {
    names->clear();
    for (long j = 0; j < cols; ++j) names->push_back(ColumnName("actions", cols, j));
  }
  return {{"actions", cols, ""}};
}

void CheckNumSamples(const Reader& r, hid_t group, const std::string& where, long rows) {
  long long num_samples = 0;
  if (r.ReadIntAttribute(group, "num_samples", where, &num_samples)) {
    SECURE_CHECK(num_samples == rows, r.path() << ": " << where
                                               << ": attribute num_samples = " << num_samples
                                               << ", but the data hold " << rows << " rows");
  }
}

// Appends the rows of `columns` (one vector per matrix row) to `m` from column `at`.
void Place(const std::vector<std::vector<float>>& columns, Eigen::Index at, Eigen::MatrixXf* m) {
  for (std::size_t i = 0; i < columns.size(); ++i)
    for (std::size_t t = 0; t < columns[i].size(); ++t)
      (*m)(static_cast<Eigen::Index>(i), at + static_cast<Eigen::Index>(t)) = columns[i][t];
}

struct Chunk {
  std::vector<std::vector<float>> states, actions;
};

// Reads data/demo_*: the selected obs columns and action columns of every demo.
TrajectorySet ReadDemos(const Reader& r, const std::vector<std::string>& state_features,
                        const std::vector<std::string>& action_features, bool need_actions) {
  const Handle data =
      r.OpenGroup(r.file(), "data", "data", "robomimic demonstrations: data/demo_<i>/obs/<key>");
  const std::vector<std::string> demos = DemoNames(r, data.get());
  TrajectorySet set;
  set.source = r.path();
  std::vector<Key> obs_keys, action_keys;
  std::vector<Column> obs_columns, action_columns;
  std::vector<Chunk> chunks;
  long total = 0;
  for (std::size_t d = 0; d < demos.size(); ++d) {
    const std::string where = "data/" + demos[d];
    const Handle demo = r.OpenGroup(data.get(), demos[d], where, "a demo");
    const Handle obs = r.OpenGroup(demo.get(), "obs", where + "/obs", "the demo's observations");
    if (d == 0) {
      obs_keys = r.Keys(obs.get(), where + "/obs");
      obs_columns = r.Resolve(obs_keys, state_features, where + "/obs", &set.state_features);
    }
    long rows = -1;
    std::string rows_from;
    Chunk chunk;
    r.ReadColumns(obs.get(), where + "/obs", obs_keys, obs_columns, &rows_from, &rows,
                  &chunk.states);
    if (need_actions) {
      if (d == 0) {
        long action_rows = 0, cols = 0;
        r.OpenFloatDataset(demo.get(), "actions", where + "/actions", &action_rows, &cols);
        std::vector<std::string> names;
        action_keys = ActionKeys(r, data.get(), cols, &names);
        // Action columns by name: the attribute's names (or actions[j]), or "actions" for all.
        std::map<std::string, long> col_of;
        for (std::size_t j = 0; j < names.size(); ++j) col_of.emplace(names[j], long(j));
        const std::vector<std::string> wanted = action_features.empty() ? names : action_features;
        for (const std::string& name : wanted) {
          const auto it = col_of.find(name);
          if (it == col_of.end() && name == "actions") {
            for (std::size_t j = 0; j < names.size(); ++j) {
              set.action_features.push_back(names[j]);
              action_columns.push_back({0, long(j)});
            }
            continue;
          }
          SECURE_CHECK(it != col_of.end(),
                       r.path() << ": " << where << "/actions: no action column '" << Excerpt(name)
                                << "'; the columns are: " << Excerpt(Join(names), 400));
          SECURE_CHECK(std::find(set.action_features.begin(), set.action_features.end(), name) ==
                           set.action_features.end(),
                       r.path() << ": " << where << "/actions: column '" << Excerpt(name)
                                << "' is selected twice");
          set.action_features.push_back(name);
          action_columns.push_back({0, it->second});
        }
      }
      r.ReadColumns(demo.get(), where, action_keys, action_columns, &rows_from, &rows,
                    &chunk.actions);
    }
    SECURE_CHECK(rows > 0, r.path() << ": " << where << ": empty demo (0 steps)");
    CheckNumSamples(r, demo.get(), where, rows);
    set.episode_begin.push_back(total);
    total += rows;
    chunks.push_back(std::move(chunk));
  }
  set.episode_begin.push_back(total);
  set.states.resize(static_cast<Eigen::Index>(set.state_features.size()), total);
  set.actions.resize(static_cast<Eigen::Index>(set.action_features.size()), total);
  for (std::size_t d = 0; d < chunks.size(); ++d) {
    Place(chunks[d].states, set.episode_begin[d], &set.states);
    Place(chunks[d].actions, set.episode_begin[d], &set.actions);
  }
  return set;
}

}  // namespace

namespace internal {

Hdf5Contents InspectHdf5InProcess(const std::string& path) {
  const Reader r(path);
  Hdf5Contents c;
  if (r.KindOf(r.file(), "data") != H5I_BADID) {
    // The first demo's keys and actions, by their types and shapes: no values are read, and a
    // key that is no (T,) or (T, k) float dataset (robomimic's images) is listed, not an error.
    const Handle data =
        r.OpenGroup(r.file(), "data", "data", "robomimic demonstrations: data/demo_<i>/obs/<key>");
    const std::string first = DemoNames(r, data.get()).front();
    const std::string where = "data/" + first;
    const Handle demo = r.OpenGroup(data.get(), first, where, "a demo");
    const Handle obs = r.OpenGroup(demo.get(), "obs", where + "/obs", "the demo's observations");
    for (const Key& k : r.Keys(obs.get(), where + "/obs")) {
      if (!k.problem.empty()) {
        c.unreadable_obs_keys.push_back(k.name);
        continue;
      }
      for (long j = 0; j < k.cols; ++j)
        c.observation_features.push_back(ColumnName(k.name, k.cols, j));
    }
    long rows = 0, cols = 0;
    r.OpenFloatDataset(demo.get(), "actions", where + "/actions", &rows, &cols);
    ActionKeys(r, data.get(), cols, &c.action_features);
    c.has_demonstrations = true;
  }
  if (r.KindOf(r.file(), "safety") != H5I_BADID) {
    const Handle safety = r.OpenGroup(r.file(), "safety", "safety", "labelled state sets");
    c.state_sets = r.Children(safety.get(), "safety");
  }
  SECURE_CHECK(c.has_demonstrations || !c.state_sets.empty(),
               path << ": neither group 'data' (demonstrations) nor 'safety' (state sets)");
  return c;
}

TrajectorySet ReadHdf5TrajectoriesInProcess(const std::string& path,
                                   const std::vector<std::string>& state_features,
                                   const std::vector<std::string>& action_features) {
  const Reader r(path);
  return ReadDemos(r, state_features, action_features, true);
}

StateSet ReadHdf5StateSetInProcess(const std::string& path,
                                   const std::vector<std::string>& features,
                                   const std::string& label) {
  const Reader r(path);
  StateSet set;
  set.source = path;
  if (r.KindOf(r.file(), "safety") == H5I_BADID) {
    // No labelled sets: the states of every demo step, as a demonstrations CSV read as states.
    SECURE_CHECK(r.KindOf(r.file(), "data") != H5I_BADID,
                 path << ": neither group 'safety' (state sets) nor 'data' (demonstrations)");
    TrajectorySet demos = ReadDemos(r, features, {}, false);
    set.features = std::move(demos.state_features);
    set.states = std::move(demos.states);
    return set;
  }
  const Handle safety = r.OpenGroup(r.file(), "safety", "safety", "labelled state sets");
  const std::vector<std::string> labels = r.Children(safety.get(), "safety");
  std::string chosen;
  if (std::find(labels.begin(), labels.end(), label) != labels.end()) {
    chosen = label;
  } else {
    SECURE_CHECK(labels.size() == 1, path << ": "
                                          << (label.empty() ? "name the state set to read"
                                                            : "no state set 'safety/" + label + "'")
                                          << "; the file has " << labels.size() << ": "
                                          << Excerpt(Join(labels), 400));
    chosen = labels.front();
  }
  const std::string where = "safety/" + chosen;
  const Handle group = r.OpenGroup(safety.get(), chosen, where, "a labelled state set");
  const Handle obs = r.OpenGroup(group.get(), "obs", where + "/obs", "the set's states");
  const std::vector<Key> keys = r.Keys(obs.get(), where + "/obs");
  const std::vector<Column> columns = r.Resolve(keys, features, where + "/obs", &set.features);
  long rows = -1;
  std::string rows_from;
  std::vector<std::vector<float>> values;
  r.ReadColumns(obs.get(), where + "/obs", keys, columns, &rows_from, &rows, &values);
  SECURE_CHECK(rows > 0, path << ": " << where << ": 0 states");
  CheckNumSamples(r, group.get(), where, rows);
  set.states.resize(static_cast<Eigen::Index>(set.features.size()), rows);
  Place(values, 0, &set.states);
  return set;
}

}  // namespace internal

}  // namespace secure::data
