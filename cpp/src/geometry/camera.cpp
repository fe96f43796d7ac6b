#include "bsp/geometry/camera.hpp"

#include <cmath>
#include <limits>

#include "bsp/common/parallel.hpp"

namespace bsp {

double Intrinsics::focal() const { return width / (2.0 * std::tan(fov_deg * M_PI / 360.0)); }

namespace {
inline void project_cam(const Mat3& Rt, const Vec3& tc, double f, double cx, double cy,
                        const Vec3& p, double* uv) {
  const Vec3 c = Rt * (p - tc);
  if (!(c.x() > 0.0)) {  // behind the camera (or NaN input)
    uv[0] = uv[1] = std::numeric_limits<double>::quiet_NaN();
    return;
  }
  uv[0] = cx + f * c.y() / c.x();
  uv[1] = cy - f * c.z() / c.x();
}
}  // namespace

void project_point(const Transform& cam, const Intrinsics& k, const Vec3& p, double* uv) {
  project_cam(cam.R.transpose(), cam.t, k.focal(), k.width / 2, k.height / 2, p, uv);
}

void project_batch(const double* points, std::size_t n, const double* cams, std::size_t kc,
                   const Intrinsics& k, double* uv) {
  const double f = k.focal(), cx = k.width / 2, cy = k.height / 2;
  parallel_for(n, 8192, [&](std::size_t lo, std::size_t hi) {
    std::size_t cached = SIZE_MAX;
    Mat3 Rt = Mat3::Identity();
    Vec3 tc = Vec3::Zero();
    for (std::size_t i = lo; i < hi; ++i) {
      const std::size_t ci = i / kc;
      if (ci != cached) {
        const Transform c = transform_from_array(cams + 6 * ci);
        Rt = c.R.transpose(), tc = c.t, cached = ci;
      }
      project_cam(Rt, tc, f, cx, cy, Eigen::Map<const Vec3>(points + 3 * i), uv + 2 * i);
    }
  });
}

void in_frame_batch(const double* uv, std::size_t frames, std::size_t joints, double width,
                    double height, std::uint8_t* out) {
  parallel_for(frames, 8192, [&](std::size_t lo, std::size_t hi) {
    for (std::size_t f = lo; f < hi; ++f) {
      const double* p = uv + f * joints * 2;
      bool finite = true, u0 = false, v0 = false, u1 = false, v1 = false;
      for (std::size_t j = 0; j < joints; ++j) {
        const double u = p[2 * j], v = p[2 * j + 1];
        finite = finite && std::isfinite(u) && std::isfinite(v);
        u0 = u0 || u >= 0, v0 = v0 || v >= 0, u1 = u1 || u <= width, v1 = v1 || v <= height;
      }
      out[f] = finite && u0 && v0 && u1 && v1;
    }
  });
}

}  // namespace bsp
