// Helpers shared by the render passes (render_scene.cpp, render_body.cpp), defined in
// render_common.cpp, render_scene.cpp and render_body.cpp; tests/cpp/test_synth.cpp checks
// them by hand.
#pragma once
#include <cstdint>
#include <limits>
#include <vector>

#include "bsp/synth/render.hpp"

namespace bsp::render {

// Nearest hit t > 0 of origin + t * dir with the capsule, or -1. `dir` must be unit length.
double intersect_capsule(const Vec3& origin, const Vec3& dir, const Vec3& a, const Vec3& b,
                         double radius);
// Smooth value noise in [-1, 1] (deterministic hash of the lattice).
double value_noise(const Vec3& p);
// Lambert shading of a base colour (0..255) with a unit normal, world or road frame alike.
Vec3 shade(const Vec3& rgb, const Vec3& normal, const Vec3& sun_dir, const Lighting& light);

// The nearest street surface along one pixel ray (render_scene.cpp).
struct Hit {
  double t = std::numeric_limits<double>::infinity();  // +inf: sky
  Vec3 normal = Vec3::UnitZ();
  std::uint8_t tag = 0;
  Vec3 rgb = Vec3::Zero();
  double texture = 0;
  Pattern pattern = Pattern::Plain;
};

// The static street as the background pass sees it from one camera: the primitives that
// can be in view (those wholly behind the camera plane dropped) and the camera in the road
// frame. render_background casts every pixel through `cast`; body_visibility casts only
// the few pixels it needs through the same function, so each gets the same bits.
class StreetView {
 public:
  StreetView(const Scene& full, const Camera& cam);  // checks scene and camera
  // The hit of pixel (i, j); `world_dir` receives the ray's (unnormalised) world direction
  // and `road_dir` its road-frame one (the hit point is origin() + t * road_dir).
  Hit cast(int i, int j, Vec3& world_dir, Vec3& road_dir) const;
  // render_background's depth of pixel (i, j): camera-x distance, +inf for sky.
  float depth(int i, int j) const;
  const Scene& scene() const { return scene_; }
  const Vec3& origin() const { return origin_; }
  const Mat3& road_rt() const { return road_rt_; }

 private:
  const Camera& cam_;
  Mat3 road_rt_;
  Vec3 origin_;
  Scene scene_;
};

// Pixel rectangle: rows [i0, i1), columns [j0, j1) (render_body.cpp).
struct PixelBox {
  int i0 = 0, i1 = 0, j0 = 0, j1 = 0;
  bool empty() const { return i0 >= i1 || j0 >= j1; }
};

// Conservative pixel bounds of each of n capsules (empty ones never reach a pixel) and
// their union in `all` (empty when none does).
void body_bounds(const Camera& cam, const Capsule* caps, std::size_t n,
                 std::vector<PixelBox>& boxes, PixelBox& all);

}  // namespace bsp::render
