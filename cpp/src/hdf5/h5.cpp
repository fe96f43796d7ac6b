#include "hdf5/h5.hpp"

#include <algorithm>
#include <mutex>

namespace bsp::h5 {
namespace {

// Collects HDF5's error stack into one line (the innermost reasons).
herr_t walk_cb(unsigned n, const H5E_error2_t* e, void* data) {
  auto* s = static_cast<std::string*>(data);
  if (n < 3) {
    if (!s->empty()) *s += "; ";
    *s += e->desc ? e->desc : "?";
    if (e->func_name) *s += std::string(" (") + e->func_name + ")";
  }
  return 0;
}

[[noreturn]] void fail(const std::string& what) {
  std::string reason;
  H5Ewalk2(H5E_DEFAULT, H5E_WALK_DOWNWARD, walk_cb, &reason);
  H5Eclear2(H5E_DEFAULT);
  throw Hdf5Error(what + (reason.empty() ? "" : ": " + reason));
}

void quiet() {
  static std::once_flag once;
  std::call_once(once, [] {
    // No library shutdown at process exit: after a failed flush (disk full) libhdf5 cannot
    // free the file and its atexit handler crashed the process (exit 139 instead of 1).
    // Every file is closed explicitly by the code that opened it. (Only effective while
    // the library is not yet initialised; it is a no-op otherwise.)
    H5dont_atexit();
    H5Eset_auto2(H5E_DEFAULT, nullptr, nullptr);
  });
}

hid_t check(hid_t id, const std::string& what) {
  if (id < 0) fail(what);
  return id;
}

void check_status(herr_t st, const std::string& what) {
  if (st < 0) fail(what);
}

Handle str_type() {
  Handle t(check(H5Tcopy(H5T_C_S1), "H5Tcopy"), H5Tclose);
  check_status(H5Tset_size(t.id(), H5T_VARIABLE), "H5Tset_size");
  check_status(H5Tset_cset(t.id(), H5T_CSET_UTF8), "H5Tset_cset");
  return t;
}

hid_t native(Type t) {
  switch (t) {
    case Type::F32: return H5T_NATIVE_FLOAT;
    case Type::F64: return H5T_NATIVE_DOUBLE;
    case Type::I32: return H5T_NATIVE_INT32;
    case Type::I64: return H5T_NATIVE_INT64;
    case Type::U8: return H5T_NATIVE_UINT8;
    case Type::Bool: return H5T_NATIVE_UINT8;  // stored as uint8 0/1 (h5py reads uint8)
    case Type::Str: break;
  }
  throw Hdf5Error("internal: no native type for strings");
}

Handle scalar_space() { return Handle(check(H5Screate(H5S_SCALAR), "H5Screate"), H5Sclose); }

Handle simple_space(const std::vector<hsize_t>& shape) {
  return Handle(check(H5Screate_simple(static_cast<int>(shape.size()), shape.data(), nullptr),
                      "H5Screate_simple"),
                H5Sclose);
}

// The strings' C pointers, for HDF5's variable-length string writes.
std::vector<const char*> c_strings(const std::vector<std::string>& values) {
  std::vector<const char*> ptrs(values.size());
  for (std::size_t i = 0; i < values.size(); ++i) ptrs[i] = values[i].c_str();
  return ptrs;
}

}  // namespace

std::string Group::where(const std::string& name) const {
  return file_ + ":" + (path_ == "/" ? "" : path_) + "/" + name;
}

Group Group::create_group(const std::string& name) const {
  Handle g(check(H5Gcreate2(h_.id(), name.c_str(), H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT),
                 "cannot create group " + where(name)),
           H5Gclose);
  return Group(std::move(g), (path_ == "/" ? "" : path_) + "/" + name, file_);
}

Handle Group::create_dataset(const std::string& name, Type type,
                             const std::vector<hsize_t>& shape, hsize_t chunk_rows,
                             const Compression& c) const {
  Handle space = simple_space(shape);
  Handle dcpl(check(H5Pcreate(H5P_DATASET_CREATE), "H5Pcreate"), H5Pclose);
  if (!shape.empty() && shape[0] > 0) {
    std::vector<hsize_t> chunk = shape;
    chunk[0] = std::max<hsize_t>(1, std::min(chunk_rows, shape[0]));
    check_status(H5Pset_chunk(dcpl.id(), static_cast<int>(chunk.size()), chunk.data()),
                 "cannot set chunks of " + where(name));
    if (c.deflate) {
      check_status(H5Pset_shuffle(dcpl.id()), "H5Pset_shuffle " + where(name));
      check_status(H5Pset_deflate(dcpl.id(), static_cast<unsigned>(c.level)),
                   "H5Pset_deflate " + where(name));
    }
  }
  return Handle(check(H5Dcreate2(h_.id(), name.c_str(), native(type), space.id(), H5P_DEFAULT,
                                 dcpl.id(), H5P_DEFAULT),
                      "cannot create dataset " + where(name)),
                H5Dclose);
}

void Group::write_rows(const Handle& ds, const std::string& name, Type type,
                       const std::vector<hsize_t>& shape, hsize_t row0, hsize_t rows,
                       const void* data) const {
  if (rows == 0) return;
  Handle file_space(check(H5Dget_space(ds.id()), "H5Dget_space " + where(name)), H5Sclose);
  std::vector<hsize_t> start(shape.size(), 0), count = shape;
  start[0] = row0, count[0] = rows;
  check_status(H5Sselect_hyperslab(file_space.id(), H5S_SELECT_SET, start.data(), nullptr,
                                   count.data(), nullptr),
               "cannot select rows of " + where(name));
  Handle mem = simple_space(count);
  check_status(H5Dwrite(ds.id(), native(type), mem.id(), file_space.id(), H5P_DEFAULT, data),
               "cannot write " + where(name));
}

void Group::write_chunk(const Handle& ds, const std::string& name,
                        const std::vector<hsize_t>& offset,
                        const std::vector<std::uint8_t>& packed) const {
  check_status(H5Dwrite_chunk(ds.id(), H5P_DEFAULT, 0, offset.data(), packed.size(), packed.data()),
               "cannot write a chunk of " + where(name));
}

void Group::write_strings(const std::string& name, const std::vector<std::string>& values) const {
  const std::vector<const char*> ptrs = c_strings(values);
  Handle type = str_type();
  Handle space = simple_space({values.size()});
  Handle ds(check(H5Dcreate2(h_.id(), name.c_str(), type.id(), space.id(), H5P_DEFAULT,
                             H5P_DEFAULT, H5P_DEFAULT),
                  "cannot create dataset " + where(name)),
            H5Dclose);
  if (!values.empty())
    check_status(H5Dwrite(ds.id(), type.id(), H5S_ALL, H5S_ALL, H5P_DEFAULT, ptrs.data()),
                 "cannot write " + where(name));
}

void Group::write_attr(const std::string& name, hid_t type, const Handle& space,
                       const void* data) const {
  Handle a(check(H5Acreate2(h_.id(), name.c_str(), type, space.id(), H5P_DEFAULT, H5P_DEFAULT),
                 "cannot create attribute " + where(name)),
           H5Aclose);
  check_status(H5Awrite(a.id(), type, data), "cannot write attribute " + where(name));
}

void Group::attr(const std::string& name, const std::string& value) const {
  const char* p = value.c_str();
  write_attr(name, str_type().id(), scalar_space(), &p);
}

void Group::attr(const std::string& name, double value) const {
  write_attr(name, H5T_NATIVE_DOUBLE, scalar_space(), &value);
}

void Group::attr(const std::string& name, std::int64_t value) const {
  attr(name, std::vector<std::int64_t>{value});
}

void Group::attr(const std::string& name, const std::vector<std::string>& values) const {
  const std::vector<const char*> ptrs = c_strings(values);
  write_attr(name, str_type().id(), simple_space({values.size()}), ptrs.data());
}

void Group::attr(const std::string& name, const std::vector<std::int64_t>& values) const {
  Handle space = values.size() == 1 ? scalar_space() : simple_space({values.size()});
  write_attr(name, H5T_NATIVE_INT64, space, values.data());
}

File File::create(const std::string& path) {
  quiet();
  File f;
  f.path_ = path;
  f.h_ = Handle(check(H5Fcreate(path.c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, H5P_DEFAULT),
                      "cannot create HDF5 file " + path),
                H5Fclose);
  return f;
}

Group File::root() const {
  Handle g(check(H5Gopen2(h_.id(), "/", H5P_DEFAULT), "cannot open / of " + path_), H5Gclose);
  return Group(std::move(g), "/", path_);
}

void File::close() {
  if (h_.id() < 0) return;
  check_status(H5Fflush(h_.id(), H5F_SCOPE_GLOBAL), "cannot flush " + path_);
  h_.reset();
}

}  // namespace bsp::h5
