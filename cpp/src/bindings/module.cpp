#include <algorithm>
#include <map>

#include "bsp/common/diagnostics.hpp"
#include "bsp/common/errors.hpp"
#include "bsp/common/parallel.hpp"
#include "common.hpp"

namespace bsp::py_bind {

static std::map<std::string, BindFn>& registry() {
  static std::map<std::string, BindFn> r;  // ordered: bindings run in name order
  return r;
}

int register_binding(const char* name, BindFn fn) {
  registry()[name] = fn;
  return 0;
}

void run_bindings(py::module_& m) {
  for (auto& [name, fn] : registry()) fn(m);
}

std::string shape_str(const py::array& a) {
  std::string s = "(";
  for (py::ssize_t i = 0; i < a.ndim(); ++i) {
    if (i) s += ", ";
    s += std::to_string(a.shape(i));
  }
  if (a.ndim() == 1) s += ",";
  return s + ")";
}

std::size_t leading_count(const py::array& a, const std::vector<py::ssize_t>& tail,
                          const char* name, const char* expected) {
  const auto nt = static_cast<py::ssize_t>(tail.size());
  bool ok = a.ndim() >= nt;
  for (py::ssize_t i = 0; ok && i < nt; ++i)
    ok = tail[i] < 0 || a.shape(a.ndim() - nt + i) == tail[i];
  if (!ok)
    throw py::value_error(std::string(name) + ": expected shape " + expected + ", got " +
                          shape_str(a));
  std::size_t n = 1;
  for (py::ssize_t i = 0; i < a.ndim() - nt; ++i) n *= static_cast<std::size_t>(a.shape(i));
  return n;
}

}  // namespace bsp::py_bind

PYBIND11_MODULE(_core, m) {
  namespace py = pybind11;
  m.doc() = "bsp_fast C++ core (private: use the bsp_fast package)";

  auto base = py::register_exception<bsp::Error>(m, "Error", PyExc_RuntimeError);
  py::register_exception<bsp::CsvParseError>(m, "CsvParseError", base.ptr());
  py::register_exception<bsp::VideoDecodeError>(m, "VideoDecodeError", base.ptr());
  py::register_exception<bsp::VideoEncodeError>(m, "VideoEncodeError", base.ptr());
  py::register_exception<bsp::ApngError>(m, "ApngError", base.ptr());
  py::register_exception<bsp::Hdf5Error>(m, "Hdf5Error", base.ptr());
  py::register_exception<bsp::MotionError>(m, "MotionError", base.ptr());
  // Exceptions carried as values (a shard's media failure) are raised again by type.
  using Kind = bsp::ErrorKind;
  py::enum_<Kind>(m, "ErrorKind", "The type of an exception carried as a value.")
      .value("Error", Kind::Error)
      .value("CsvParseError", Kind::CsvParseError)
      .value("VideoDecodeError", Kind::VideoDecodeError)
      .value("VideoEncodeError", Kind::VideoEncodeError)
      .value("ApngError", Kind::ApngError)
      .value("Hdf5Error", Kind::Hdf5Error)
      .value("MotionError", Kind::MotionError)
      .value("ValueError", Kind::ValueError)
      .value("MemoryError", Kind::MemoryError)
      .value("RuntimeError", Kind::RuntimeError);
  m.def("raise_error", [](Kind kind, const std::string& message) {
        if (kind == Kind::MemoryError) {  // std::bad_alloc has no message to carry
          PyErr_SetString(PyExc_MemoryError, message.c_str());
          throw py::error_already_set();
        }
        bsp::throw_error(kind, message);
      }, py::arg("kind"), py::arg("message"),
      "Raises the exception of `kind` (the same Python type the core raises) with `message`.");

  m.def("library_versions", &bsp::library_versions,
        "Versions of the C/C++ libraries the core is linked with.");
  m.def("set_num_threads", &bsp::set_num_threads, py::arg("n"),
        "Threads used by the core's parallel kernels (0 = all cores).");
  m.def("num_threads", &bsp::num_threads, "Threads the core's parallel kernels use.");

  bsp::py_bind::run_bindings(m);
}
