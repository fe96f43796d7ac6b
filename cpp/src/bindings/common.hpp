// Shared helpers of the binding files. Each file registers its functions with BSP_BINDING,
// so adding an area means adding a file; module.cpp calls them in name order.
#pragma once
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <string>
#include <vector>

namespace bsp::py_bind {
namespace py = pybind11;

using BindFn = void (*)(py::module_&);
int register_binding(const char* name, BindFn fn);
void run_bindings(py::module_& m);

template <class T>
using CArray = py::array_t<T, py::array::c_style | py::array::forcecast>;

// "(4, 2)" for messages.
std::string shape_str(const py::array& a);

// Checks that `a` ends in `tail` dims (use -1 for any) and returns the product of the rest.
std::size_t leading_count(const py::array& a, const std::vector<py::ssize_t>& tail,
                          const char* name, const char* expected);

// A new C-contiguous array of `shape`.
template <class T>
CArray<T> empty(const std::vector<py::ssize_t>& shape) {
  return CArray<T>(shape);
}

}  // namespace bsp::py_bind

// BSP_BINDING(area) { m.def(...); } inside namespace bsp::py_bind: the area's function, which
// sees the helpers above and `py` unqualified, registered for run_bindings.
#define BSP_BINDING(name)                                                          \
  static void bsp_bind_##name(pybind11::module_& m);                               \
  [[maybe_unused]] static const int bsp_bind_reg_##name =                          \
      ::bsp::py_bind::register_binding(#name, &bsp_bind_##name);                   \
  static void bsp_bind_##name(pybind11::module_& m)
