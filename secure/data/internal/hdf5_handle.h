#pragma once
// Pieces of the HDF5 reader and writer (hdf5_read.cc, hdf5_write.cc): an owned HDF5 identifier,
// HDF5's error printing turned off, its innermost error message, and data types' names and
// checks. INTERNAL: include only from secure/data/hdf5_*.cc; no public header includes <hdf5.h>.
#include <hdf5.h>

#include <string>

#include "secure/common/excerpt.h"

namespace secure::data::hdf5 {

// Owns an HDF5 identifier and closes it with the function of its kind.
class Handle {
 public:
  Handle() = default;
  Handle(hid_t id, herr_t (*close)(hid_t)) : id_(id), close_(close) {}
  ~Handle() { Reset(); }
  Handle(Handle&& other) noexcept : id_(other.id_), close_(other.close_) { other.id_ = -1; }
  Handle& operator=(Handle&& other) noexcept {
    if (this != &other) {
      Reset();
      id_ = other.id_;
      close_ = other.close_;
      other.id_ = -1;
    }
    return *this;
  }
  Handle(const Handle&) = delete;
  Handle& operator=(const Handle&) = delete;
  hid_t get() const { return id_; }
  bool ok() const { return id_ >= 0; }

 private:
  void Reset() {
    if (id_ >= 0 && close_ != nullptr) close_(id_);
    id_ = -1;
  }
  hid_t id_ = -1;
  herr_t (*close_)(hid_t) = nullptr;
};

// Turns off HDF5's printing of its error stack to stderr while a file is read or written: our
// own one-line messages replace it. Restores the previous handler.
class QuietHdf5 {
 public:
  QuietHdf5() {
    H5Eget_auto2(H5E_DEFAULT, &func_, &data_);
    H5Eset_auto2(H5E_DEFAULT, nullptr, nullptr);
  }
  ~QuietHdf5() { H5Eset_auto2(H5E_DEFAULT, func_, data_); }
  QuietHdf5(const QuietHdf5&) = delete;
  QuietHdf5& operator=(const QuietHdf5&) = delete;

 private:
  H5E_auto2_t func_ = nullptr;
  void* data_ = nullptr;
};

// The innermost message of HDF5's current error stack ("" if none), for "corrupt file" errors.
inline std::string Hdf5Reason() {
  std::string reason;
  H5Ewalk2(
      H5E_DEFAULT, H5E_WALK_UPWARD,
      [](unsigned n, const H5E_error2_t* e, void* out) -> herr_t {
        if (n == 0 && e->desc != nullptr) *static_cast<std::string*>(out) = e->desc;
        return 0;
      },
      &reason);
  return reason.empty() ? std::string() : " (HDF5: " + Excerpt(reason) + ")";
}

// True for IEEE binary32 or binary64 in either byte order (what H5T_NATIVE_DOUBLE converts
// from without a custom float conversion).
inline bool IsIeeeFloat(hid_t type) {
  for (hid_t ieee : {H5T_IEEE_F32LE, H5T_IEEE_F32BE, H5T_IEEE_F64LE, H5T_IEEE_F64BE})
    if (H5Tequal(type, ieee) > 0) return true;
  return false;
}

inline const char* ClassName(H5T_class_t c) {
  switch (c) {
    case H5T_INTEGER:
      return "integer";
    case H5T_FLOAT:
      return "float";
    case H5T_STRING:
      return "string";
    case H5T_BITFIELD:
      return "bitfield";
    case H5T_OPAQUE:
      return "opaque";
    case H5T_COMPOUND:
      return "compound";
    case H5T_REFERENCE:
      return "reference";
    case H5T_ENUM:
      return "enum";
    case H5T_VLEN:
      return "variable-length";
    case H5T_ARRAY:
      return "array";
    default:
      return "unknown";
  }
}

// "uint8", "int64", "float32", "string", ...: the numpy name where there is one.
inline std::string TypeName(hid_t type, H5T_class_t c) {
  const std::size_t bits = type >= 0 ? 8 * H5Tget_size(type) : 0;
  if (c == H5T_INTEGER) {
    return std::string(H5Tget_sign(type) == H5T_SGN_NONE ? "uint" : "int") +
           std::to_string(bits);
  }
  if (c == H5T_FLOAT) return "float" + std::to_string(bits);
  return ClassName(c);
}

}  // namespace secure::data::hdf5
