#pragma once
// Builds small HDF5 files with the HDF5 C API for the tests: well-formed robomimic layouts and
// every kind of bad file, written from the test itself (no binary files in the repository).
//
//   Hdf5TestFile f(path);
//   f.Doubles("data/demo_0/obs/pos", {3, 2}, {1, 2, 3, 4, 5, 6});   // (3, 2) float64
//   f.Floats("data/demo_0/actions", {3}, {0, 1, 2});                 // (3,) float32
//   f.UInt8s("data/demo_0/obs/image", {3, 4, 4, 3}, pixels);         // robomimic's images
//   f.IntAttribute("data/demo_0", "num_samples", 3);
//   // closed by the destructor
//
// Intermediate groups are created as needed.

#include <algorithm>
#include <hdf5.h>

#include <gtest/gtest.h>

#include <string>
#include <vector>

namespace secure::test {

class Hdf5TestFile {
 public:
  explicit Hdf5TestFile(const std::string& path)
      : file_(H5Fcreate(path.c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, H5P_DEFAULT)) {
    EXPECT_GE(file_, 0) << path;
    lcpl_ = H5Pcreate(H5P_LINK_CREATE);
    H5Pset_create_intermediate_group(lcpl_, 1);
  }
  ~Hdf5TestFile() {
    H5Pclose(lcpl_);
    H5Fclose(file_);
  }
  Hdf5TestFile(const Hdf5TestFile&) = delete;
  Hdf5TestFile& operator=(const Hdf5TestFile&) = delete;

  void Group(const std::string& path) {
    const hid_t g = H5Gcreate2(file_, path.c_str(), lcpl_, H5P_DEFAULT, H5P_DEFAULT);
    EXPECT_GE(g, 0) << path;
    H5Gclose(g);
  }
  void Doubles(const std::string& path, const std::vector<hsize_t>& dims,
               const std::vector<double>& values) {
    Write(path, dims, H5T_IEEE_F64LE, H5T_NATIVE_DOUBLE, values.data());
  }
  void Floats(const std::string& path, const std::vector<hsize_t>& dims,
              const std::vector<float>& values) {
    Write(path, dims, H5T_IEEE_F32LE, H5T_NATIVE_FLOAT, values.data());
  }
  void Ints(const std::string& path, const std::vector<hsize_t>& dims,
            const std::vector<long long>& values) {
    Write(path, dims, H5T_STD_I64LE, H5T_NATIVE_LLONG, values.data());
  }
  void UInt8s(const std::string& path, const std::vector<hsize_t>& dims,
              const std::vector<unsigned char>& values) {
    Write(path, dims, H5T_STD_U8LE, H5T_NATIVE_UCHAR, values.data());
  }
  void IntAttribute(const std::string& object, const std::string& name, long long value) {
    const hid_t o = H5Oopen(file_, object.c_str(), H5P_DEFAULT);
    const hid_t space = H5Screate(H5S_SCALAR);
    const hid_t a = H5Acreate2(o, name.c_str(), H5T_STD_I64LE, space, H5P_DEFAULT, H5P_DEFAULT);
    EXPECT_GE(H5Awrite(a, H5T_NATIVE_LLONG, &value), 0) << object << " " << name;
    H5Aclose(a);
    H5Sclose(space);
    H5Oclose(o);
  }

  // A demo of T steps: obs/<key> (T, widths[k]) float64 holding row-major 100 k + t + j / 10,
  // actions (T, 2) float32, num_samples = T.
  void Demo(int index, long steps, const std::vector<std::string>& keys = {"pos", "vel"},
            const std::vector<hsize_t>& widths = {2, 1}) {
    const std::string demo = "data/demo_" + std::to_string(index);
    for (std::size_t k = 0; k < keys.size(); ++k) {
      std::vector<double> v;
      for (long t = 0; t < steps; ++t)
        for (hsize_t j = 0; j < widths[k]; ++j)
          v.push_back(100.0 * double(k) + double(t) + double(j) / 10);
      Doubles(demo + "/obs/" + keys[k], {hsize_t(steps), widths[k]}, v);
    }
    std::vector<float> a;
    for (long t = 0; t < steps; ++t) {
      a.push_back(float(t));
      a.push_back(-float(t));
    }
    Floats(demo + "/actions", {hsize_t(steps), 2}, a);
    IntAttribute(demo, "num_samples", steps);
  }

  // A chunked float64 dataset of shape `dims` whose data are never written: a few KB on disk
  // whatever the declared shape (the memory bomb of issue 34).
  void Unwritten(const std::string& path, const std::vector<hsize_t>& dims) {
    const hid_t space = H5Screate_simple(int(dims.size()), dims.data(), nullptr);
    const hid_t dcpl = H5Pcreate(H5P_DATASET_CREATE);
    std::vector<hsize_t> chunk(dims.size(), 1);
    chunk[0] = std::min<hsize_t>(1024, dims[0]);
    H5Pset_chunk(dcpl, int(chunk.size()), chunk.data());
    const hid_t d = H5Dcreate2(file_, path.c_str(), H5T_IEEE_F64LE, space, lcpl_, dcpl,
                               H5P_DEFAULT);
    EXPECT_GE(d, 0) << path;
    H5Dclose(d);
    H5Pclose(dcpl);
    H5Sclose(space);
  }

 private:
  void Write(const std::string& path, const std::vector<hsize_t>& dims, hid_t file_type,
             hid_t mem_type, const void* values) {
    const hid_t space = H5Screate_simple(int(dims.size()), dims.data(), nullptr);
    const hid_t d =
        H5Dcreate2(file_, path.c_str(), file_type, space, lcpl_, H5P_DEFAULT, H5P_DEFAULT);
    EXPECT_GE(d, 0) << path;
    EXPECT_GE(H5Dwrite(d, mem_type, H5S_ALL, H5S_ALL, H5P_DEFAULT, values), 0) << path;
    H5Dclose(d);
    H5Sclose(space);
  }

  hid_t file_;
  hid_t lcpl_;
};

}  // namespace secure::test
