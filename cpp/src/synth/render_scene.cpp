// Background pass: one ray per pixel against the static street, in the road frame (where
// every box is axis-aligned and every cylinder vertical).
#include <algorithm>
#include <cmath>
#include <limits>

#include "bsp/common/parallel.hpp"
#include "bsp/synth/render.hpp"
#include "render_internal.hpp"

namespace bsp::render {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();
constexpr double kEps = 1e-6;

double frac(double x) { return x - std::floor(x); }

void hit_ground(const Scene& sc, const Vec3& o, const Vec3& d, Hit& hit) {
  if (!(d.z() < 0 && o.z() > 0)) return;
  const double t = -o.z() / d.z();
  if (!(t > kEps && t < hit.t)) return;
  const double s = o.x() + t * d.x(), w = o.y() + t * d.y();
  for (auto it = sc.bands.rbegin(); it != sc.bands.rend(); ++it) {
    if (w < it->w0 || w >= it->w1) continue;
    if (it->dash_period > 0 &&
        !(frac((s - it->dash_phase) / it->dash_period) * it->dash_period < it->dash_on))
      continue;
    hit = Hit{t, Vec3::UnitZ(), it->tag, it->rgb, it->texture, Pattern::Plain};
    return;
  }
  hit = Hit{t, Vec3::UnitZ(), 0, Vec3::Zero(), 0, Pattern::Plain};
}

void hit_box(const Box& b, const Vec3& o, const Vec3& d, Hit& hit) {
  double tmin = -kInf, tmax = kInf;
  int axis = -1;
  double sign = 0;
  for (int k = 0; k < 3; ++k) {
    if (std::abs(d[k]) < 1e-12) {
      if (o[k] < b.lo[k] || o[k] > b.hi[k]) return;
      continue;
    }
    double t1 = (b.lo[k] - o[k]) / d[k], t2 = (b.hi[k] - o[k]) / d[k];
    if (t1 > t2) std::swap(t1, t2);
    if (t1 > tmin) tmin = t1, axis = k, sign = d[k] > 0 ? -1.0 : 1.0;
    tmax = std::min(tmax, t2);
  }
  if (axis < 0 || tmax < tmin || !(tmin > kEps) || !(tmin < hit.t)) return;
  Vec3 n = Vec3::Zero();
  n[axis] = sign;
  hit = Hit{tmin, n, b.tag, b.rgb, b.texture, b.pattern};
}

void hit_cylinder(const Cylinder& c, const Vec3& o, const Vec3& d, Hit& hit) {
  const double dx = o.x() - c.s, dy = o.y() - c.w;
  const double a = d.x() * d.x() + d.y() * d.y();
  const double b = dx * d.x() + dy * d.y(), cc = dx * dx + dy * dy - c.radius * c.radius;
  if (a > 1e-12) {
    const double h = b * b - a * cc;
    if (h >= 0) {
      const double t = (-b - std::sqrt(h)) / a, z = o.z() + t * d.z();
      if (t > kEps && t < hit.t && z >= c.z0 && z <= c.z1) {
        const Vec3 n((dx + t * d.x()) / c.radius, (dy + t * d.y()) / c.radius, 0.0);
        hit = Hit{t, n, c.tag, c.rgb, c.texture, Pattern::Plain};
        return;
      }
    }
  }
  if (d.z() < 0 && o.z() > c.z1) {  // top cap
    const double t = (c.z1 - o.z()) / d.z();
    const double px = dx + t * d.x(), py = dy + t * d.y();
    if (t > kEps && t < hit.t && px * px + py * py <= c.radius * c.radius)
      hit = Hit{t, Vec3::UnitZ(), c.tag, c.rgb, c.texture, Pattern::Plain};
  }
}

void hit_sphere(const Sphere& s, const Vec3& o, const Vec3& d, Hit& hit) {
  const Vec3 oc = o - s.centre;
  const double a = d.dot(d), b = oc.dot(d), c = oc.dot(oc) - s.radius * s.radius;
  const double h = b * b - a * c;
  if (h < 0) return;
  const double t = (-b - std::sqrt(h)) / a;
  if (t > kEps && t < hit.t)
    hit = Hit{t, (oc + t * d) / s.radius, s.tag, s.rgb, s.texture, Pattern::Plain};
}

// Window grids on building walls, glass on car cabins, joints between paving tiles.
Vec3 apply_pattern(const Hit& h, const Vec3& p) {
  const bool wall = std::abs(h.normal.z()) < 0.5;
  switch (h.pattern) {
    case Pattern::Windows: {
      if (!wall || p.z() < 3.3) return h.rgb;  // ground floor: plain
      const double a = std::abs(h.normal.x()) > 0.5 ? p.y() : p.x();
      const double fa = frac(a / 3.1), fz = frac(p.z() / 3.3);
      if (fa > 0.22 && fa < 0.78 && fz > 0.3 && fz < 0.82) return Vec3(52, 66, 84);
      return h.rgb;
    }
    case Pattern::Glass:
      return wall ? Vec3(38, 46, 58) : h.rgb;
    case Pattern::Tiles:
      if (wall) return h.rgb;
      return (frac(p.x() / 0.6) < 0.05 || frac(p.y() / 0.6) < 0.05) ? h.rgb * 0.82 : h.rgb;
    default:
      return h.rgb;
  }
}

Vec3 sky_colour(const Lighting& l, const Vec3& dir_world) {
  const double e = std::clamp(dir_world.z() / dir_world.norm() * 2.5, 0.0, 1.0);
  return l.sky_horizon + (l.sky_zenith - l.sky_horizon) * std::pow(e, 0.7);
}

void store(const Vec3& c, std::uint8_t* px) {
  for (int k = 0; k < 3; ++k)
    px[k] = static_cast<std::uint8_t>(std::lround(std::clamp(c[k], 0.0, 255.0)));
}

// Largest camera-forward distance of a road-frame box's corners.
double ahead(const Vec3& lo, const Vec3& hi, const Vec3& origin, const Vec3& fwd) {
  double d = -origin.dot(fwd);
  for (int k = 0; k < 3; ++k) d += std::max(lo[k] * fwd[k], hi[k] * fwd[k]);
  return d;
}

// Every pixel ray has camera-x > 0, so primitives wholly behind the camera plane can never
// be hit: drop them once per image (about half of the street).
Scene cull_behind(const Scene& sc, const Vec3& origin, const Vec3& fwd) {
  Scene out;
  out.road = sc.road, out.bands = sc.bands, out.light = sc.light;
  for (const auto& b : sc.boxes)
    if (ahead(b.lo, b.hi, origin, fwd) > 0) out.boxes.push_back(b);
  for (const auto& c : sc.cylinders) {
    const Vec3 lo(c.s - c.radius, c.w - c.radius, c.z0), hi(c.s + c.radius, c.w + c.radius, c.z1);
    if (ahead(lo, hi, origin, fwd) > 0) out.cylinders.push_back(c);
  }
  for (const auto& s : sc.spheres)
    if ((s.centre - origin).dot(fwd) + s.radius > 0) out.spheres.push_back(s);
  return out;
}

}  // namespace

StreetView::StreetView(const Scene& full, const Camera& cam)
    : cam_(cam), road_rt_(full.road.R.transpose()) {
  check_scene(full);
  check_camera(cam);
  origin_ = road_rt_ * (cam.pose.t - full.road.t);
  scene_ = cull_behind(full, origin_, road_rt_ * cam.pose.R.col(0));
}

// Out of line so that every caller runs the same machine code: the background pass and
// body_visibility must agree on each pixel's depth to the bit (a compiler allowed to fuse
// multiply-adds could otherwise fuse them differently in two inlined copies).
[[gnu::noinline]] Hit StreetView::cast(int i, int j, Vec3& world_dir, Vec3& road_dir) const {
  world_dir = cam_.pose.R * pixel_direction(cam_, i, j);
  road_dir = road_rt_ * world_dir;
  Hit h;
  hit_ground(scene_, origin_, road_dir, h);
  for (const auto& b : scene_.boxes) hit_box(b, origin_, road_dir, h);
  for (const auto& c : scene_.cylinders) hit_cylinder(c, origin_, road_dir, h);
  for (const auto& s : scene_.spheres) hit_sphere(s, origin_, road_dir, h);
  return h;
}

float StreetView::depth(int i, int j) const {
  Vec3 dw, d;
  const Hit h = cast(i, j, dw, d);
  return h.t < kInf ? static_cast<float>(h.t) : std::numeric_limits<float>::infinity();
}

void render_background(const Scene& full, const Camera& cam, std::uint8_t* rgb,
                       std::uint8_t* tags, float* depth, int threads) {
  const StreetView view(full, cam);
  const Scene& sc = view.scene();
  const int W = cam.width(), H = cam.height();
  const Vec3 sun = view.road_rt() * sc.light.sun.normalized();
  parallel_for(static_cast<std::size_t>(H), 8, [&](std::size_t lo, std::size_t hi) {
    for (std::size_t i = lo; i < hi; ++i) {
      for (int j = 0; j < W; ++j) {
        const std::size_t px = i * static_cast<std::size_t>(W) + static_cast<std::size_t>(j);
        Vec3 dw, d;
        const Hit h = view.cast(static_cast<int>(i), j, dw, d);
        if (!(h.t < kInf)) {
          store(sky_colour(sc.light, dw), rgb + 3 * px);
          tags[px] = 13;  // Sky
          depth[px] = std::numeric_limits<float>::infinity();
          continue;
        }
        const Vec3 p = view.origin() + h.t * d;
        Vec3 c = apply_pattern(h, p);
        if (h.texture > 0)
          c *= 1.0 + h.texture * (0.6 * value_noise(p * 1.3) + 0.4 * value_noise(p * 5.1));
        c = shade(c, h.normal, sun, sc.light);
        const double fog = 1.0 - std::exp(-h.t * d.norm() / sc.light.fog_distance);
        c += (sc.light.sky_horizon - c) * fog;
        store(c, rgb + 3 * px);
        tags[px] = h.tag;
        depth[px] = static_cast<float>(h.t);
      }
    }
  }, threads);
}

}  // namespace bsp::render
