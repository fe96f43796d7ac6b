// Shared pieces of the two render passes: pixel rays, value noise, shading, capsules.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <stdexcept>
#include <string>

#include "bsp/synth/render.hpp"
#include "render_internal.hpp"

namespace bsp::render {

void check_camera(const Camera& cam) {
  if (!(cam.k.width > 0 && cam.k.height > 0 && cam.k.fov_deg > 0 && cam.k.fov_deg < 180))
    throw std::invalid_argument("camera: need width > 0, height > 0 and 0 < fov < 180");
}

void check_lighting(const Lighting& light) {
  if (!(light.fog_distance > 0)) throw std::invalid_argument("light: fog distance must be > 0");
  if (!(light.sun.norm() > 0)) throw std::invalid_argument("light: sun direction must be non-zero");
}

void check_scene(const Scene& scene) {
  check_lighting(scene.light);
  for (std::size_t i = 0; i < scene.boxes.size(); ++i) {
    const int pattern = static_cast<int>(scene.boxes[i].pattern);
    if (pattern < 0 || pattern > 3)
      throw std::invalid_argument("boxes row " + std::to_string(i) + ": pattern must be 0..3");
  }
}

Vec3 pixel_direction(const Camera& cam, int i, int j) {
  const double f = cam.k.focal();
  return Vec3(1.0, (j + 0.5 - cam.k.width / 2) / f, -(i + 0.5 - cam.k.height / 2) / f);
}

namespace {
// Integer lattice hash (unsigned arithmetic: wrap-around is defined) mapped to [-1, 1].
double lattice(std::int64_t x, std::int64_t y, std::int64_t z) {
  std::uint32_t h = static_cast<std::uint32_t>(x) * 73856093u ^
                    static_cast<std::uint32_t>(y) * 19349663u ^
                    static_cast<std::uint32_t>(z) * 83492791u;
  h ^= h >> 16;
  h *= 0x85ebca6bu;
  h ^= h >> 13;
  h *= 0xc2b2ae35u;
  h ^= h >> 16;
  return static_cast<double>(h) * (2.0 / 4294967295.0) - 1.0;
}

double smooth(double t) { return t * t * (3.0 - 2.0 * t); }
}  // namespace

double value_noise(const Vec3& p) {
  const double fx = std::floor(p.x()), fy = std::floor(p.y()), fz = std::floor(p.z());
  const auto x = static_cast<std::int64_t>(fx), y = static_cast<std::int64_t>(fy),
             z = static_cast<std::int64_t>(fz);
  const double u = smooth(p.x() - fx), v = smooth(p.y() - fy), w = smooth(p.z() - fz);
  auto lerp = [](double a, double b, double t) { return a + (b - a) * t; };
  const double x00 = lerp(lattice(x, y, z), lattice(x + 1, y, z), u);
  const double x10 = lerp(lattice(x, y + 1, z), lattice(x + 1, y + 1, z), u);
  const double x01 = lerp(lattice(x, y, z + 1), lattice(x + 1, y, z + 1), u);
  const double x11 = lerp(lattice(x, y + 1, z + 1), lattice(x + 1, y + 1, z + 1), u);
  return lerp(lerp(x00, x10, v), lerp(x01, x11, v), w);
}

Vec3 shade(const Vec3& rgb, const Vec3& normal, const Vec3& sun_dir, const Lighting& light) {
  const double lambert = std::max(0.0, normal.dot(sun_dir));
  return rgb * (light.ambient + light.diffuse * lambert);
}

// Ray against a capsule (swept sphere), after Inigo Quilez's capIntersect: the infinite
// cylinder first, then whichever end sphere the hit falls beyond.
double intersect_capsule(const Vec3& ro, const Vec3& rd, const Vec3& pa, const Vec3& pb,
                         double ra) {
  const Vec3 ba = pb - pa, oa = ro - pa;
  const double baba = ba.dot(ba);
  if (baba > 1e-12) {
    const double bard = ba.dot(rd), baoa = ba.dot(oa), rdoa = rd.dot(oa), oaoa = oa.dot(oa);
    const double a = baba - bard * bard;
    const double b = baba * rdoa - baoa * bard;
    const double c = baba * oaoa - baoa * baoa - ra * ra * baba;
    const double h = b * b - a * c;
    if (a > 1e-12 && h >= 0.0) {
      const double t = (-b - std::sqrt(h)) / a;
      const double y = baoa + t * bard;
      if (y > 0.0 && y < baba) return t > 0 ? t : -1.0;
    }
  }
  // End spheres: test both and keep the nearest (also covers rays parallel to the axis).
  double best = -1.0;
  for (const Vec3* centre : {&pa, &pb}) {
    const Vec3 oc = ro - *centre;
    const double b = rd.dot(oc), c = oc.dot(oc) - ra * ra, h = b * b - c;
    if (h < 0.0) continue;
    const double t = -b - std::sqrt(h);
    if (t > 0.0 && (best < 0.0 || t < best)) best = t;
    if (baba <= 1e-12) break;
  }
  return best;
}

}  // namespace bsp::render
