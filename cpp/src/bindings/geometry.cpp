// Geometry kernels. Broadcasting and friendly shape errors live in bsp_fast/geometry.py;
// these check sizes again so misuse of the private module cannot read out of bounds.
#include "bsp/geometry/camera.hpp"
#include "bsp/geometry/kinematics.hpp"
#include "bsp/geometry/skeleton.hpp"
#include "common.hpp"

namespace bsp::py_bind {
namespace {

std::vector<py::ssize_t> with_tail(const py::array& a, std::size_t drop,
                                   std::initializer_list<py::ssize_t> tail) {
  std::vector<py::ssize_t> s(a.shape(), a.shape() + a.ndim() - static_cast<py::ssize_t>(drop));
  s.insert(s.end(), tail);
  return s;
}

void check_repeat(std::size_t have, std::size_t k, std::size_t n, const char* name) {
  if (k == 0 || have * k != n)
    throw py::value_error(std::string(name) + ": " + std::to_string(have) + " items repeated " +
                          std::to_string(k) + " times do not make " + std::to_string(n));
}

CArray<double> rotation_matrix(const CArray<double>& pyr) {
  const std::size_t n = leading_count(pyr, {3}, "pyr", "(..., 3)");
  auto out = empty<double>(with_tail(pyr, 1, {3, 3}));
  {
    py::gil_scoped_release nogil;
    rotation_matrices(pyr.data(), out.mutable_data(), n);
  }
  return out;
}

CArray<double> rotation_to_euler(const CArray<double>& R) {
  const std::size_t n = leading_count(R, {3, 3}, "R", "(..., 3, 3)");
  auto out = empty<double>(with_tail(R, 2, {3}));
  {
    py::gil_scoped_release nogil;
    rotations_to_euler(R.data(), out.mutable_data(), n);
  }
  return out;
}

CArray<double> compose_flat(const CArray<double>& a, std::size_t ka, const CArray<double>& b,
                            std::size_t kb, std::size_t n) {
  check_repeat(leading_count(a, {6}, "a", "(..., 6)"), ka, n, "a");
  check_repeat(leading_count(b, {6}, "b", "(..., 6)"), kb, n, "b");
  auto out = empty<double>({static_cast<py::ssize_t>(n), 6});
  {
    py::gil_scoped_release nogil;
    compose_batch(a.data(), ka, b.data(), kb, out.mutable_data(), n);
  }
  return out;
}

CArray<double> invert(const CArray<double>& t) {
  const std::size_t n = leading_count(t, {6}, "t", "(..., 6)");
  auto out = empty<double>(with_tail(t, 1, {6}));
  {
    py::gil_scoped_release nogil;
    invert_batch(t.data(), out.mutable_data(), n);
  }
  return out;
}

CArray<double> transform_points_flat(const CArray<double>& t, std::size_t kt,
                                     const CArray<double>& p, std::size_t kp, std::size_t n) {
  check_repeat(leading_count(t, {6}, "t", "(..., 6)"), kt, n, "t");
  check_repeat(leading_count(p, {3}, "p", "(..., 3)"), kp, n, "p");
  auto out = empty<double>({static_cast<py::ssize_t>(n), 3});
  {
    py::gil_scoped_release nogil;
    transform_points_batch(t.data(), kt, p.data(), kp, out.mutable_data(), n);
  }
  return out;
}

CArray<double> fk(const CArray<double>& relative, const std::optional<CArray<double>>& root,
                  std::size_t kr, const CArray<std::int32_t>& parents) {
  const std::size_t joints = static_cast<std::size_t>(parents.size());
  if (parents.ndim() != 1)
    throw py::value_error("parents: expected a 1-D array, got shape " + shape_str(parents));
  const std::string exp = "(..., " + std::to_string(joints) + ", 6)";
  const std::size_t frames = leading_count(relative, {static_cast<py::ssize_t>(joints), 6},
                                           "relative", exp.c_str());
  if (root) check_repeat(leading_count(*root, {6}, "root", "(..., 6)"), kr, frames, "root");
  try {
    check_parents(parents.data(), joints);
  } catch (const std::invalid_argument& e) {
    throw py::value_error(e.what());
  }
  auto out = empty<double>(with_tail(relative, 0, {}));
  {
    py::gil_scoped_release nogil;
    forward_kinematics(relative.data(), frames, joints, parents.data(),
                       root ? root->data() : nullptr, root ? kr : 1, out.mutable_data());
  }
  return out;
}

CArray<double> project_flat(const CArray<double>& points, const CArray<double>& cams,
                            std::size_t kc, double width, double height, double fov) {
  const std::size_t n = leading_count(points, {3}, "points", "(..., 3)");
  check_repeat(leading_count(cams, {6}, "camera_transform", "(..., 6)"), kc, n,
               "camera_transform");
  if (!(width > 0 && height > 0 && fov > 0 && fov < 180))
    throw py::value_error("project: need width > 0, height > 0 and 0 < fov < 180");
  auto out = empty<double>(with_tail(points, 1, {2}));
  {
    py::gil_scoped_release nogil;
    project_batch(points.data(), n, cams.data(), kc, Intrinsics{width, height, fov},
                  out.mutable_data());
  }
  return out;
}

CArray<bool> in_frame(const CArray<double>& uv, double width, double height) {
  const std::size_t frames = leading_count(uv, {-1, 2}, "uv", "(..., J, 2)");
  const auto joints = static_cast<std::size_t>(uv.shape(uv.ndim() - 2));
  auto out = empty<bool>(with_tail(uv, 2, {}));
  {
    py::gil_scoped_release nogil;
    static_assert(sizeof(bool) == 1, "bool must be one byte");
    in_frame_batch(uv.data(), frames, joints, width, height,
                   reinterpret_cast<std::uint8_t*>(out.mutable_data()));
  }
  return out;
}

}  // namespace

BSP_BINDING(geometry) {
  namespace sk = bsp::skeleton;
  m.def("rotation_matrix", &rotation_matrix, py::arg("pyr"),
        "(..., 3) [pitch, yaw, roll] degrees -> (..., 3, 3) CARLA rotation matrices.");
  m.def("rotation_to_euler", &rotation_to_euler, py::arg("R"),
        "(..., 3, 3) rotation matrices -> (..., 3) [pitch, yaw, roll] degrees.");
  m.def("compose_flat", &compose_flat, py::arg("a"), py::arg("ka"), py::arg("b"),
        py::arg("kb"), py::arg("n"), "out[i] = a[i // ka] o b[i // kb], (n, 6).");
  m.def("invert", &invert, py::arg("t"), "(..., 6) transforms -> their inverses.");
  m.def("transform_points_flat", &transform_points_flat, py::arg("t"), py::arg("kt"),
        py::arg("p"), py::arg("kp"), py::arg("n"), "out[i] = t[i // kt] applied to p[i // kp].");
  m.def("forward_kinematics", &fk, py::arg("relative"), py::arg("root"), py::arg("kr"),
        py::arg("parents"),
        "(..., J, 6) parent-relative bones -> (..., J, 6) component-space transforms; root of "
        "frame f is root[f // kr].");
  m.def("project_flat", &project_flat, py::arg("points"), py::arg("cams"), py::arg("kc"),
        py::arg("width"), py::arg("height"), py::arg("fov"),
        "(..., 3) world points -> (..., 2) pixels; camera of point i is cams[i // kc].");
  m.def("in_frame", &in_frame, py::arg("uv"), py::arg("width"), py::arg("height"),
        "(..., J, 2) pixels -> (...) the recorder's loose in_frame flag.");
  m.attr("JOINT_NAMES") = py::cast(std::vector<std::string>(sk::kNames.begin(), sk::kNames.end()));
  m.attr("PARENTS") = py::cast(std::vector<int>(sk::kParents.begin(), sk::kParents.end()));
  m.attr("FLIP_PERMUTATION") = py::cast(std::vector<int>(sk::kFlip.begin(), sk::kFlip.end()));
}

}  // namespace bsp::py_bind
