// The bsp-synth ray caster. Scenes arrive as flat float64 tables (one row per primitive,
// columns documented in each docstring); bsp_fast/synth/scene.py builds them and
// bsp_fast/synth/clip.py calls these. Only type conversion here: the core checks the
// options (bsp::render::check_scene, check_camera, check_lighting).
#include <cmath>
#include <string>

#include "bsp/synth/render.hpp"
#include "common.hpp"

namespace bsp::py_bind {
namespace {
namespace rd = bsp::render;

std::size_t rows(const CArray<double>& a, py::ssize_t cols, const char* name) {
  if (a.ndim() != 2 || a.shape(1) != cols)
    throw py::value_error(std::string(name) + ": expected shape (n, " + std::to_string(cols) +
                          "), got " + shape_str(a));
  return static_cast<std::size_t>(a.shape(0));
}

std::uint8_t tag_of(double v, const char* name, std::size_t row) {
  if (!(v >= 0 && v <= 255 && v == std::floor(v)))
    throw py::value_error(std::string(name) + " row " + std::to_string(row) +
                          ": tag must be an integer in [0, 255], got " + std::to_string(v));
  return static_cast<std::uint8_t>(v);
}

Vec3 v3(const double* p) { return Vec3(p[0], p[1], p[2]); }

rd::Lighting make_light(const CArray<double>& light) {
  if (light.size() != 12)
    throw py::value_error("light: expected 12 values, got " + shape_str(light));
  const double* L = light.data();
  return rd::Lighting{v3(L), L[3], L[4], v3(L + 5), v3(L + 8), L[11]};
}

rd::Scene make_scene(const CArray<double>& road, const CArray<double>& bands,
                     const CArray<double>& boxes, const CArray<double>& cyls,
                     const CArray<double>& spheres, const CArray<double>& light) {
  if (road.size() != 6) throw py::value_error("road: expected 6 values, got " + shape_str(road));
  rd::Scene sc;
  sc.road = transform_from_array(road.data());
  sc.light = make_light(light);
  for (std::size_t i = 0, n = rows(bands, 10, "bands"); i < n; ++i) {
    const double* r = bands.data() + 10 * i;
    sc.bands.push_back({r[0], r[1], tag_of(r[2], "bands", i), v3(r + 3), r[6], r[7], r[8], r[9]});
  }
  for (std::size_t i = 0, n = rows(boxes, 12, "boxes"); i < n; ++i) {
    const double* r = boxes.data() + 12 * i;
    // A pattern is a whole number; anything else becomes -1, which the core refuses.
    const bool whole = r[10] == std::floor(r[10]) && std::fabs(r[10]) < 1e9;
    sc.boxes.push_back({v3(r).cwiseMin(v3(r + 3)), v3(r).cwiseMax(v3(r + 3)),
                        tag_of(r[6], "boxes", i), v3(r + 7),
                        static_cast<rd::Pattern>(whole ? static_cast<int>(r[10]) : -1), r[11]});
  }
  for (std::size_t i = 0, n = rows(cyls, 10, "cylinders"); i < n; ++i) {
    const double* r = cyls.data() + 10 * i;
    sc.cylinders.push_back(
        {r[0], r[1], r[2], r[3], r[4], tag_of(r[5], "cylinders", i), v3(r + 6), r[9]});
  }
  for (std::size_t i = 0, n = rows(spheres, 9, "spheres"); i < n; ++i) {
    const double* r = spheres.data() + 9 * i;
    sc.spheres.push_back({v3(r), r[3], tag_of(r[4], "spheres", i), v3(r + 5), r[8]});
  }
  return sc;
}

rd::Camera make_camera(const CArray<double>& cam, int width, int height, double fov) {
  if (cam.size() != 6) throw py::value_error("camera: expected 6 values, got " + shape_str(cam));
  return rd::Camera{transform_from_array(cam.data()),
                    Intrinsics{static_cast<double>(width), static_cast<double>(height), fov}};
}

py::tuple render_background(const CArray<double>& road, const CArray<double>& bands,
                            const CArray<double>& boxes, const CArray<double>& cyls,
                            const CArray<double>& spheres, const CArray<double>& light,
                            const CArray<double>& camera, int width, int height, double fov,
                            int threads) {
  const rd::Scene sc = make_scene(road, bands, boxes, cyls, spheres, light);
  const rd::Camera cam = make_camera(camera, width, height, fov);
  rd::check_scene(sc);  // before the outputs are sized from the camera
  rd::check_camera(cam);
  auto rgb = empty<std::uint8_t>({height, width, 3});
  auto tags = empty<std::uint8_t>({height, width});
  auto depth = empty<float>({height, width});
  {
    py::gil_scoped_release nogil;
    rd::render_background(sc, cam, rgb.mutable_data(), tags.mutable_data(),
                          depth.mutable_data(), threads);
  }
  return py::make_tuple(rgb, tags, depth);
}

py::tuple render_bodies(const CArray<std::uint8_t>& bg_rgb, const CArray<std::uint8_t>& bg_tags,
                        const CArray<float>& bg_depth, const CArray<double>& camera, double fov,
                        const CArray<double>& light, const CArray<double>& capsules,
                        const CArray<double>& colours, int threads) {
  if (bg_rgb.ndim() != 3 || bg_rgb.shape(2) != 3)
    throw py::value_error("bg_rgb: expected shape (H, W, 3), got " + shape_str(bg_rgb));
  const auto H = bg_rgb.shape(0), W = bg_rgb.shape(1);
  if (bg_tags.ndim() != 2 || bg_tags.shape(0) != H || bg_tags.shape(1) != W ||
      bg_depth.ndim() != 2 || bg_depth.shape(0) != H || bg_depth.shape(1) != W)
    throw py::value_error("bg_tags / bg_depth: expected shape (H, W) like bg_rgb");
  if (capsules.ndim() != 3 || capsules.shape(2) != 7)
    throw py::value_error("capsules: expected shape (frames, P, 7), got " + shape_str(capsules));
  const auto frames = capsules.shape(0), P = capsules.shape(1);
  if (colours.ndim() != 2 || colours.shape(0) != P || colours.shape(1) != 3)
    throw py::value_error("colours: expected shape (P, 3), got " + shape_str(colours));
  const rd::Camera cam = make_camera(camera, static_cast<int>(W), static_cast<int>(H), fov);
  const rd::Lighting lit = make_light(light);
  rd::check_camera(cam);
  rd::check_lighting(lit);
  std::vector<rd::Capsule> caps(static_cast<std::size_t>(frames * P));
  for (std::size_t k = 0; k < caps.size(); ++k) {
    const double* c = capsules.data() + 7 * k;
    caps[k] = rd::Capsule{v3(c), v3(c + 3), c[6], v3(colours.data() + 3 * (k % P))};
  }
  auto rgb = empty<std::uint8_t>({frames, H, W, 3});
  auto tags = empty<std::uint8_t>({frames, H, W});
  auto visible = empty<bool>({frames});
  {
    py::gil_scoped_release nogil;
    rd::render_bodies(cam, lit, bg_rgb.data(), bg_tags.data(), bg_depth.data(),
                      caps.data(), static_cast<std::size_t>(P), static_cast<std::size_t>(frames),
                      rgb.mutable_data(), tags.mutable_data(),
                      reinterpret_cast<std::uint8_t*>(visible.mutable_data()), threads);
  }
  return py::make_tuple(rgb, tags, visible);
}

py::array_t<bool> body_visibility(const CArray<double>& road, const CArray<double>& bands,
                                  const CArray<double>& boxes, const CArray<double>& cyls,
                                  const CArray<double>& spheres, const CArray<double>& light,
                                  const CArray<double>& camera, int width, int height,
                                  double fov, const CArray<double>& capsules, int threads) {
  const rd::Scene sc = make_scene(road, bands, boxes, cyls, spheres, light);
  const rd::Camera cam = make_camera(camera, width, height, fov);
  if (capsules.ndim() != 3 || capsules.shape(2) != 7)
    throw py::value_error("capsules: expected shape (frames, P, 7), got " + shape_str(capsules));
  const auto frames = capsules.shape(0), P = capsules.shape(1);
  std::vector<rd::Capsule> caps(static_cast<std::size_t>(frames * P));
  for (std::size_t k = 0; k < caps.size(); ++k) {
    const double* c = capsules.data() + 7 * k;
    caps[k] = rd::Capsule{v3(c), v3(c + 3), c[6], Vec3::Zero()};  // colour: not drawn
  }
  auto visible = empty<bool>({frames});
  {
    py::gil_scoped_release nogil;
    rd::body_visibility(sc, cam, caps.data(), static_cast<std::size_t>(P),
                        static_cast<std::size_t>(frames),
                        reinterpret_cast<std::uint8_t*>(visible.mutable_data()), threads);
  }
  return visible;
}

}  // namespace

BSP_BINDING(render) {
  m.def("render_background", &render_background, py::arg("road"), py::arg("bands"),
        py::arg("boxes"), py::arg("cylinders"), py::arg("spheres"), py::arg("light"),
        py::arg("camera"), py::arg("width"), py::arg("height"), py::arg("fov"),
        py::arg("threads") = 0,
        "Ray-casts a static street -> (rgb (H,W,3) u8, tags (H,W) u8, depth (H,W) f32).\n"
        "road (6,) world-from-road transform; rows in the road frame (s along, w across):\n"
        "bands (n,10) [w0,w1,tag,r,g,b,dash_period,dash_on,dash_phase,texture] on z=0;\n"
        "boxes (n,12) [s0,w0,z0,s1,w1,z1,tag,r,g,b,pattern,texture] (pattern 0 plain, 1 "
        "windows, 2 glass, 3 tiles);\ncylinders (n,10) [s,w,z0,z1,radius,tag,r,g,b,texture];"
        "\nspheres (n,9) [s,w,z,radius,tag,r,g,b,texture];\nlight (12,) [sun_x,sun_y,sun_z "
        "(world), ambient, diffuse, zenith rgb, horizon rgb, fog_distance].\nDepth is "
        "camera-x distance, +inf for sky (tag 13).");
  m.def("render_bodies", &render_bodies, py::arg("bg_rgb"), py::arg("bg_tags"),
        py::arg("bg_depth"), py::arg("camera"), py::arg("fov"), py::arg("light"),
        py::arg("capsules"), py::arg("colours"), py::arg("threads") = 0,
        "Draws the pedestrian over the background for each frame -> (rgb (F,H,W,3) u8, "
        "tags (F,H,W) u8, visible (F,) bool).\ncapsules (F,P,7) world [ax,ay,az,bx,by,bz,"
        "radius]; colours (P,3) 0..255; tag 4 where a capsule is in front of the "
        "background depth.");
  m.def("body_visibility", &body_visibility, py::arg("road"), py::arg("bands"),
        py::arg("boxes"), py::arg("cylinders"), py::arg("spheres"), py::arg("light"),
        py::arg("camera"), py::arg("width"), py::arg("height"), py::arg("fov"),
        py::arg("capsules"), py::arg("threads") = 0,
        "render_bodies' visible flags (F,) bool over render_background's images of the "
        "scene, without rendering them: only the background pixels the capsules' rays hit "
        "are cast. Arguments as render_background's, then capsules (F,P,7) as "
        "render_bodies'.");
}

}  // namespace bsp::py_bind
