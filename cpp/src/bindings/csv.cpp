// data.csv reader/writer bindings. The reader's columns are handed to numpy without a copy
// (each array owns its std::vector through a capsule); bsp_fast/csvio.py wraps the result.
#include "bsp/csv/columns.hpp"
#include "bsp/csv/csv.hpp"
#include "common.hpp"

namespace bsp::py_bind {
namespace {

// A numpy array owning `v` (moved to the heap); `dt` may reinterpret it (uint8 -> bool).
template <class T>
py::array take(std::vector<T>&& v, const std::vector<std::size_t>& shape,
               const py::dtype& dt = py::dtype::of<T>()) {
  auto* owner = new std::vector<T>(std::move(v));
  py::capsule cap(owner, [](void* p) { delete static_cast<std::vector<T>*>(p); });
  return py::array(dt, std::vector<py::ssize_t>(shape.begin(), shape.end()), {}, owner->data(),
                   cap);
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
    check_utf8(t);  // the strings below become str
  }
  py::dict data, valid, strs;
  for (const std::string& name : t.columns_present) {
    const PoseColumn col = pose_column(t, name);
    const auto shape = col.spec->shape(t.rows);
    const py::str key(name);
    if (col.floats) data[key] = take(std::move(*col.floats), shape);
    if (col.ints) data[key] = take(std::move(*col.ints), shape);
    if (col.bools) {
      data[key] = take(std::move(*col.bools), shape, py::dtype("?"));
      valid[key] = take(std::move(*col.valid), shape, py::dtype("?"));
    }
    if (col.strings)
      strs[key] = py::make_tuple(py::cast(col.strings->values),
                                 take(std::move(col.strings->codes), shape));
  }
  py::dict out;
  out["path"] = t.path;
  out["rows"] = t.rows;
  out["line"] = take(std::move(t.line), {t.rows});
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
  for (std::size_t c = 0; c < kPoseCsvColumnCount; ++c) {
    const PoseColumn col = pose_column(t, c);
    const char* name = col.spec->name;
    if (!cols.contains(name))
      throw py::value_error(std::string("write_pose_csv: missing column '") + name + "'");
    const py::handle obj = cols[name];
    if (col.floats) *col.floats = copy_array<float>(obj, name, rows * col.spec->numbers());
    if (col.ints) *col.ints = copy_array<std::int64_t>(obj, name, rows);
    if (col.bools) {
      const auto pair = py::cast<py::tuple>(obj);
      *col.bools = copy_array<std::uint8_t>(pair[0], name, rows);
      *col.valid = copy_array<std::uint8_t>(pair[1], name, rows);
    }
    if (col.strings) {
      const auto pair = py::cast<py::tuple>(obj);
      col.strings->values = pair[0].cast<std::vector<std::string>>();
      col.strings->codes = copy_array<std::int32_t>(pair[1], name, rows);
    }
  }
  py::gil_scoped_release nogil;
  write_pose_csv(path, t, threads);
}

}  // namespace

BSP_BINDING(csv) {
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

}  // namespace bsp::py_bind
