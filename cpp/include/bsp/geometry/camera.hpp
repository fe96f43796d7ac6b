// Pinhole projection of the CARLA RGB camera (docs/dataset-format.md,
// "5. Geometry conventions"): camera looks along its +x, y right, z up;
// f = W / (2 tan(fov/2)); u = W/2 + f*y/x, v = H/2 - f*z/x. No distortion, no half-pixel
// shift. Points with x <= 0 (behind the camera) project to NaN.
#pragma once
#include <cstddef>
#include <cstdint>

#include "bsp/geometry/kinematics.hpp"

namespace bsp {

struct Intrinsics {
  double width = 1600, height = 600, fov_deg = 90.0;
  double focal() const;
};

// Projects one world point through camera transform `cam` (world-from-camera).
void project_point(const Transform& cam, const Intrinsics& k, const Vec3& p, double* uv);

// n points; the camera of point i is cams[i / kc]. Output (n, 2).
void project_batch(const double* points, std::size_t n, const double* cams, std::size_t kc,
                   const Intrinsics& k, double* uv);

// The recorder's loose `in_frame` rule for `frames` poses of `joints` pixels: all finite
// AND any(u >= 0) AND any(v >= 0) AND any(u <= W) AND any(v <= H).
void in_frame_batch(const double* uv, std::size_t frames, std::size_t joints, double width,
                    double height, std::uint8_t* out);

}  // namespace bsp
