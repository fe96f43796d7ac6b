// data.csv reader/writer bindings. The reader's columns are handed to numpy without a copy
// (each array owns its std::vector through a capsule); bsp_fast/csvio.py wraps the result.
#include "../csv/csv_internal.hpp"
#include "bsp/csv/csv.hpp"
#include "bsp/common/errors.hpp"
#include "common.hpp"

namespace bsp::py_bind {
namespace {
namespace cd = bsp::csv_detail;

// A numpy array owning `v` (moved to the heap); `dt` may reinterpret it (uint8 -> bool).
template <class T>
py::array take(std::vector<T>&& v, std::vector<py::ssize_t> shape,
               const py::dtype& dt = py::dtype::of<T>()) {
  auto* owner = new std::vector<T>(std::move(v));
  py::capsule cap(owner, [](void* p) { delete static_cast<std::vector<T>*>(p); });
  return py::array(dt, std::move(shape), {}, owner->data(), cap);
}

std::vector<py::ssize_t> shape_of(const cd::ColumnSpec& s, std::size_t rows) {
  const auto n = static_cast<py::ssize_t>(rows);
  if (s.kind != cd::Kind::floats) return {n};
  if (s.outer) return {n, s.outer, s.inner};
  return {n, s.inner};
}

py::list strings(const std::vector<std::string>& values, const PoseTable& t, const char* col) {
  py::list out;
  for (const std::string& v : values) {
    PyObject* s = PyUnicode_DecodeUTF8(v.data(), static_cast<py::ssize_t>(v.size()), "strict");
    if (!s) {
      PyErr_Clear();
      throw CsvParseError(t.path + ", column '" + col + "': value " + cd::snippet(v) +
                          " is not valid UTF-8");
    }
    out.append(py::reinterpret_steal<py::str>(s));
  }
  return out;
}

py::dict read_pose_csv_py(const std::string& path, const std::vector<std::string>& columns,
                          int threads, bool check_duplicates) {
  CsvReadOptions opt;
  opt.columns = columns;
  opt.threads = threads;
  opt.check_duplicates = check_duplicates;
  PoseTable t;
  {
    py::gil_scoped_release nogil;
    t = read_pose_csv(path, opt);
  }
  py::dict data, valid, strs;
  for (const std::string& name : t.columns_present) {
    const int c = cd::column_index(name);
    const cd::ColumnSpec& s = cd::kSpecs[c];
    const cd::ColumnRef r = cd::column_ref(t, c);
    const auto shape = shape_of(s, t.rows);
    const py::str key(name);
    if (r.floats) data[key] = take(std::move(*r.floats), shape);
    if (r.ints) data[key] = take(std::move(*r.ints), shape);
    if (r.bools) {
      data[key] = take(std::move(*r.bools), shape, py::dtype("?"));
      valid[key] = take(std::move(*r.valid), shape, py::dtype("?"));
    }
    if (r.str)
      strs[key] = py::make_tuple(strings(r.str->values, t, s.name),
                                 take(std::move(r.str->codes), shape));
  }
  py::dict out;
  out["path"] = t.path;
  out["rows"] = t.rows;
  out["line"] = take(std::move(t.line), {static_cast<py::ssize_t>(t.rows)});
  out["columns"] = t.columns_present;
  out["crossing_column"] = t.crossing_column;
  out["data"] = data;
  out["valid"] = valid;
  out["strings"] = strs;
  return out;
}

// A copy of one array-like as a flat std::vector<T> of exactly `want` values.
template <class T>
std::vector<T> copy_array(const py::handle& obj, const char* name, std::size_t want) {
  const auto a = py::cast<CArray<T>>(obj);
  if (static_cast<std::size_t>(a.size()) != want)
    throw py::value_error(std::string("write_pose_csv: column '") + name + "' has " +
                          std::to_string(a.size()) + " values, expected " + std::to_string(want));
  return std::vector<T>(a.data(), a.data() + a.size());
}

void write_pose_csv_py(const std::string& path, const py::dict& cols, std::size_t rows,
                       int threads) {
  PoseTable t;
  t.rows = rows;
  for (int c = 0; c < static_cast<int>(kPoseCsvColumnCount); ++c) {
    const cd::ColumnSpec& s = cd::kSpecs[c];
    if (!cols.contains(s.name))
      throw py::value_error(std::string("write_pose_csv: missing column '") + s.name + "'");
    const py::handle col = cols[s.name];
    const cd::ColumnRef r = cd::column_ref(t, c);
    if (r.floats) *r.floats = copy_array<float>(col, s.name, rows * s.numbers());
    if (r.ints) *r.ints = copy_array<std::int64_t>(col, s.name, rows);
    if (r.bools) {
      const auto pair = py::cast<py::tuple>(col);
      *r.bools = copy_array<std::uint8_t>(pair[0], s.name, rows);
      *r.valid = copy_array<std::uint8_t>(pair[1], s.name, rows);
    }
    if (r.str) {
      const auto pair = py::cast<py::tuple>(col);
      r.str->values = pair[0].cast<std::vector<std::string>>();
      r.str->codes = copy_array<std::int32_t>(pair[1], s.name, rows);
    }
  }
  py::gil_scoped_release nogil;
  write_pose_csv(path, t, threads);
}

}  // namespace
}  // namespace bsp::py_bind

BSP_BINDING(csv) {
  using namespace bsp::py_bind;
  namespace py = pybind11;
  m.def("read_pose_csv", &read_pose_csv_py, py::arg("path"), py::arg("columns"),
        py::arg("threads"), py::arg("check_duplicates"),
        "Parse a data.csv (columns: [] = all) -> dict(path, rows, line, columns, "
        "crossing_column, data={name: array}, valid={bool column: mask}, "
        "strings={name: (values, int32 codes)}).");
  m.def("write_pose_csv", &write_pose_csv_py, py::arg("path"), py::arg("columns"),
        py::arg("rows"), py::arg("threads"),
        "Write all 24 columns as pandas to_csv(index=False) does. columns maps each canonical "
        "name to a float32/int64 array, (values, int32 codes) for strings, or (uint8 values, "
        "uint8 valid) for booleans.");
  m.attr("CSV_COLUMNS") =
      py::cast(std::vector<std::string>(bsp::kPoseCsvColumns.begin(), bsp::kPoseCsvColumns.end()));
  m.attr("CSV_CROSSING_ALIAS") = py::str(bsp::kCrossingAlias);
}
