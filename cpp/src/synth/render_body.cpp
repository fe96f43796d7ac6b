// Per-frame pass: the pedestrian's capsules over the cached background, only inside the
// pedestrian's projected bounding box, depth-tested against the background depth.
#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <vector>

#include "bsp/common/parallel.hpp"
#include "bsp/synth/render.hpp"
#include "render_internal.hpp"

namespace bsp::render {
namespace {

// Range of a / x over x in [x0, x1] (0 < x0 <= x1) and a in [a0, a1].
void ratio_range(double a0, double a1, double x0, double x1, double& lo, double& hi) {
  lo = a0 < 0 ? a0 / x0 : a0 / x1;
  hi = a1 > 0 ? a1 / x0 : a1 / x1;
}

// Conservative pixel bounds of one capsule: its camera-space bounding box, clipped to
// x >= kNear (nothing nearer can be hit by a pixel ray that far out), projected through
// the extreme y/x and z/x ratios.
PixelBox capsule_bounds(const Camera& cam, const Mat3& rt, const Capsule& c) {
  constexpr double kNear = 1e-3;
  const Vec3 ca = rt * (c.a - cam.pose.t), cb = rt * (c.b - cam.pose.t);
  const Vec3 lo = ca.cwiseMin(cb).array() - c.radius, hi = ca.cwiseMax(cb).array() + c.radius;
  if (hi.x() <= kNear) return PixelBox{};  // wholly behind the camera
  const double x0 = std::max(lo.x(), kNear), f = cam.k.focal();
  double y0, y1, z0, z1;
  ratio_range(lo.y(), hi.y(), x0, hi.x(), y0, y1);
  ratio_range(lo.z(), hi.z(), x0, hi.x(), z0, z1);
  const double u0 = cam.k.width / 2 + f * y0, u1 = cam.k.width / 2 + f * y1;
  const double v0 = cam.k.height / 2 - f * z1, v1 = cam.k.height / 2 - f * z0;
  const int W = cam.width(), H = cam.height();
  auto pix = [](double x, int n) {
    return static_cast<int>(std::clamp(std::floor(x), -1.0, static_cast<double>(n)));
  };
  PixelBox b{std::max(pix(v0, H), 0), std::min(pix(v1, H) + 1, H), std::max(pix(u0, W), 0),
             std::min(pix(u1, W) + 1, W)};
  return b.empty() ? PixelBox{} : b;
}

// Nearest capsule hit along the unit ray d from the camera, among the candidates.
double nearest(const Vec3& o, const Vec3& d, const Capsule* caps,
               const std::vector<std::size_t>& cand, std::size_t& which) {
  double best = std::numeric_limits<double>::infinity();
  for (std::size_t k : cand) {
    const double t = intersect_capsule(o, d, caps[k].a, caps[k].b, caps[k].radius);
    if (t > 0 && t < best) best = t, which = k;
  }
  return best;
}

void shade_pixel(const Capsule& c, const Vec3& p, double dist, const Vec3& sun,
                 const Lighting& light, std::uint8_t* rgb) {
  const Vec3 ba = c.b - c.a;
  const double len2 = ba.dot(ba);
  const double h = len2 > 1e-12 ? std::clamp((p - c.a).dot(ba) / len2, 0.0, 1.0) : 0.0;
  const Vec3 normal = (p - (c.a + h * ba)).normalized();
  Vec3 col = shade(c.rgb, normal, sun, light);
  col += (light.sky_horizon - col) * (1.0 - std::exp(-dist / light.fog_distance));
  for (int k = 0; k < 3; ++k)
    rgb[k] = static_cast<std::uint8_t>(std::lround(std::clamp(col[k], 0.0, 255.0)));
}

// Calls visit(px, capsule, t, d, dc) for each pixel whose ray hits one of the n capsules
// (t: distance to the nearest hit along the unit world ray d; dc: the pixel's unnormalised
// camera-axes direction), testing only the capsules whose bounds hold the pixel, row by
// row, until visit returns true. Returns whether it did. The drawing pass and the
// visibility pass both walk the pixels through this, so they agree on every hit.
template <class Visit>
bool walk_body(const Camera& cam, const Capsule* caps, std::size_t n, Visit&& visit) {
  std::vector<PixelBox> boxes;
  PixelBox all;
  body_bounds(cam, caps, n, boxes, all);
  const std::size_t W = static_cast<std::size_t>(cam.width());
  std::vector<std::size_t> row, cand;
  for (int i = all.i0; i < all.i1; ++i) {
    row.clear();
    for (std::size_t k = 0; k < n; ++k)
      if (!boxes[k].empty() && boxes[k].i0 <= i && i < boxes[k].i1) row.push_back(k);
    for (int j = all.j0; j < all.j1 && !row.empty(); ++j) {
      cand.clear();
      for (std::size_t k : row)
        if (boxes[k].j0 <= j && j < boxes[k].j1) cand.push_back(k);
      if (cand.empty()) continue;
      const Vec3 dc = pixel_direction(cam, i, j);
      const Vec3 d = cam.pose.R * dc.normalized();
      std::size_t which = n;
      const double best = nearest(cam.pose.t, d, caps, cand, which);
      if (which == n) continue;
      const std::size_t px = static_cast<std::size_t>(i) * W + static_cast<std::size_t>(j);
      if (visit(px, which, best, d, dc)) return true;
    }
  }
  return false;
}

// Draws the pedestrian's pixels that are nearer than the background; returns whether any
// pedestrian pixel was drawn.
bool draw_body(const Camera& cam, const Lighting& light, const Capsule* caps, std::size_t n,
               const float* bg_depth, std::uint8_t* rgb, std::uint8_t* tags) {
  const Vec3 sun = light.sun.normalized();
  bool any = false;
  walk_body(cam, caps, n, [&](std::size_t px, std::size_t which, double best, const Vec3& d,
                              const Vec3& dc) {
    if (!(best / dc.norm() < bg_depth[px])) return false;  // camera-x depth test
    shade_pixel(caps[which], cam.pose.t + best * d, best, sun, light, rgb + 3 * px);
    tags[px] = 4;  // Pedestrian
    any = true;
    return false;
  });
  return any;
}

// Whether the pedestrian has a pixel nearer than the background: draw_body's answer, with
// the background depth of only the pixels the body covers, each cast at most once per
// clip (`cache`, NaN = not cast yet), and the walk stopped at the first visible pixel.
bool body_visible(const StreetView& street, const Camera& cam, const Capsule* caps,
                  std::size_t n, std::vector<float>& cache) {
  const std::size_t W = static_cast<std::size_t>(cam.width());
  return walk_body(cam, caps, n, [&](std::size_t px, std::size_t, double best, const Vec3&,
                                     const Vec3& dc) {
    float& depth = cache[px];
    if (std::isnan(depth))
      depth = street.depth(static_cast<int>(px / W), static_cast<int>(px % W));
    return best / dc.norm() < depth;
  });
}

}  // namespace

void body_bounds(const Camera& cam, const Capsule* caps, std::size_t n,
                 std::vector<PixelBox>& boxes, PixelBox& all) {
  const Mat3 rt = cam.pose.R.transpose();
  boxes.assign(n, PixelBox{});
  all = PixelBox{cam.height(), 0, cam.width(), 0};
  for (std::size_t k = 0; k < n; ++k) {
    boxes[k] = capsule_bounds(cam, rt, caps[k]);
    if (boxes[k].empty()) continue;
    all = PixelBox{std::min(all.i0, boxes[k].i0), std::max(all.i1, boxes[k].i1),
                   std::min(all.j0, boxes[k].j0), std::max(all.j1, boxes[k].j1)};
  }
}

void render_bodies(const Camera& cam, const Lighting& light, const std::uint8_t* bg_rgb,
                   const std::uint8_t* bg_tags, const float* bg_depth, const Capsule* caps,
                   std::size_t caps_per_frame, std::size_t frames, std::uint8_t* rgb,
                   std::uint8_t* tags, std::uint8_t* visible, int threads) {
  check_camera(cam);
  check_lighting(light);
  const std::size_t npx = static_cast<std::size_t>(cam.width()) * cam.height();
  // Frames are independent: one block of frames per thread.
  parallel_for(frames, 1, [&](std::size_t lo, std::size_t hi) {
    for (std::size_t f = lo; f < hi; ++f) {
      std::uint8_t* out_rgb = rgb + 3 * npx * f;
      std::uint8_t* out_tags = tags + npx * f;
      std::memcpy(out_rgb, bg_rgb, 3 * npx);
      std::memcpy(out_tags, bg_tags, npx);
      visible[f] = draw_body(cam, light, caps + f * caps_per_frame, caps_per_frame, bg_depth,
                             out_rgb, out_tags);
    }
  }, threads);
}

}  // namespace bsp::render

namespace bsp::render {

void body_visibility(const Scene& scene, const Camera& cam, const Capsule* caps,
                     std::size_t caps_per_frame, std::size_t frames, std::uint8_t* visible,
                     int threads) {
  const StreetView street(scene, cam);  // checks scene and camera
  const std::size_t npx = static_cast<std::size_t>(cam.width()) * cam.height();
  // One block of frames per thread, each with its own depth cache: a pixel cast twice
  // (once per thread) gets the same depth, so the flags do not depend on the threads.
  parallel_for(frames, 16, [&](std::size_t lo, std::size_t hi) {
    std::vector<float> cache(npx, std::numeric_limits<float>::quiet_NaN());
    for (std::size_t f = lo; f < hi; ++f)
      visible[f] = body_visible(street, cam, caps + f * caps_per_frame, caps_per_frame, cache);
  }, threads);
}

}  // namespace bsp::render
