// Helpers shared by the two render passes (render_scene.cpp, render_body.cpp), defined in
// render_common.cpp; tests/cpp/test_synth.cpp checks them by hand.
#pragma once
#include "bsp/synth/render.hpp"

namespace bsp::render {

// Nearest hit t > 0 of origin + t * dir with the capsule, or -1. `dir` must be unit length.
double intersect_capsule(const Vec3& origin, const Vec3& dir, const Vec3& a, const Vec3& b,
                         double radius);
// Smooth value noise in [-1, 1] (deterministic hash of the lattice).
double value_noise(const Vec3& p);
// Lambert shading of a base colour (0..255) with a unit normal, world or road frame alike.
Vec3 shade(const Vec3& rgb, const Vec3& normal, const Vec3& sun_dir, const Lighting& light);

}  // namespace bsp::render
