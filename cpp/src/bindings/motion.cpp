// Animation import for bsp-synth --motion (retargeting lives in bsp_fast/synth/motion.py).
#include <cstring>

#include "bsp/synth/motion.hpp"
#include "common.hpp"

namespace bsp::py_bind {
namespace {

py::dict load_motion(const std::string& path, double fps, int index) {
  Motion mo;
  {
    py::gil_scoped_release nogil;
    mo = bsp::load_motion(path, fps, index);
  }
  const auto n = static_cast<py::ssize_t>(mo.names.size());
  const auto frames = static_cast<py::ssize_t>(mo.frames);
  auto rest = empty<double>({n, 4, 4});
  auto local = empty<double>({frames, n, 4, 4});
  auto parents = empty<std::int32_t>({n});
  std::memcpy(rest.mutable_data(), mo.rest.data(), mo.rest.size() * sizeof(double));
  std::memcpy(local.mutable_data(), mo.local.data(), mo.local.size() * sizeof(double));
  for (py::ssize_t j = 0; j < n; ++j) parents.mutable_data()[j] = mo.parents[j];
  py::dict out;
  out["path"] = mo.path;
  out["names"] = mo.names;
  out["parents"] = parents;
  out["rest"] = rest;
  out["local"] = local;
  out["fps"] = mo.fps;
  out["duration"] = mo.duration;
  out["animation"] = mo.animation;
  return out;
}

}  // namespace

BSP_BINDING(motion) {
  m.def("load_motion", &load_motion, py::arg("path"), py::arg("fps") = 30.0,
        py::arg("index") = 0,
        "Reads an animation file through assimp (BVH, FBX, glTF, ...) -> dict(path, names, "
        "parents (N,) int32, rest (N,4,4), local (F,N,4,4) row-major local node transforms "
        "sampled at fps, fps, duration, animation). Raises MotionError.");
}

}  // namespace bsp::py_bind
