// --verify: recompute component = M ∘ FK(relative) with M recovered from the recording's
// first row, world = walker ∘ component, and the projection of world; report the largest
// disagreement with the stored columns per recording.
#include <algorithm>
#include <cmath>

#include "bsp/common/parallel.hpp"
#include "bsp/geometry/camera.hpp"
#include "bsp/geometry/kinematics.hpp"
#include "bsp/geometry/skeleton.hpp"
#include "convert_internal.hpp"

namespace bsp::detail {
namespace {

constexpr int J = skeleton::kJoints;

Transform tf(const float* p) {
  double d[6];
  std::copy_n(p, 6, d);
  return transform_from_array(d);
}

VerifyRow verify_one(const PoseTable& t, const Recording& rec, const Intrinsics& k) {
  VerifyRow out;
  const std::size_t r0 = rec.rows.front();
  const Transform M = compose(tf(&t.pose_component[r0 * J * 6]), inverse(tf(&t.pose_relative[r0 * J * 6])));
  Transform A[J];
  for (std::size_t row : rec.rows) {
    const float* rel = &t.pose_relative[row * J * 6];
    const float* comp = &t.pose_component[row * J * 6];
    const float* world = &t.pose_world[row * J * 6];
    const float* uv = &t.pose_camera[row * J * 2];
    const Transform walker = tf(&t.walker_transform[row * 6]);
    const Transform cam = tf(&t.camera_transform[row * 6]);
    const Intrinsics kr{static_cast<double>(t.camera_width[row]), static_cast<double>(t.camera_height[row]), k.fov_deg};
    for (int j = 0; j < J; ++j) {
      const Transform r = tf(rel + 6 * j);
      A[j] = j == 0 ? compose(M, r) : compose(A[skeleton::kParents[j]], r);
      const Vec3 c(comp[6 * j], comp[6 * j + 1], comp[6 * j + 2]);
      const Vec3 w(world[6 * j], world[6 * j + 1], world[6 * j + 2]);
      out.component_mm = std::max(out.component_mm, 1000.0 * (A[j].t - c).norm());
      out.world_mm = std::max(out.world_mm, 1000.0 * (walker.R * c + walker.t - w).norm());
      double p[2];
      project_point(cam, kr, w, p);
      const bool nan_a = std::isnan(p[0]), nan_b = std::isnan(uv[2 * j]);
      if (nan_a != nan_b) out.camera_px = INFINITY;
      else if (!nan_a) out.camera_px = std::max(out.camera_px, std::hypot(p[0] - uv[2 * j], p[1] - uv[2 * j + 1]));
    }
  }
  return out;
}

}  // namespace

std::vector<VerifyRow> verify_recordings(const PoseTable& t, const Plan& plan, double fov, int threads) {
  std::vector<VerifyRow> rows(plan.recordings.size());
  const Intrinsics k{0, 0, fov};
  parallel_for(rows.size(), 1, [&](std::size_t lo, std::size_t hi) {
    for (std::size_t i = lo; i < hi; ++i) {
      const Recording& rec = plan.recordings[i];
      rows[i] = verify_one(t, rec, k);
      const std::size_t r0 = rec.rows.front();
      std::string path = t.recording.values[static_cast<std::size_t>(t.recording.codes[r0])];
      rows[i].recording = path + " (" + std::to_string(rec.camera_idx) + "_" +
                          std::to_string(rec.pedestrian_idx) + ")";
    }
  }, threads);
  return rows;
}

}  // namespace bsp::detail
