#include "bsp/kinematics.hpp"

#include <cmath>
#include <stdexcept>
#include <string>

#include "bsp/parallel.hpp"

namespace bsp {
namespace {
constexpr double kDeg = M_PI / 180.0;
constexpr double kRad = 180.0 / M_PI;
// Per-item cost is ~100 ns: below this many items threads cost more than they save.
constexpr std::size_t kMinBlock = 4096;
}  // namespace

Mat3 rotation_from_pyr(double pitch_deg, double yaw_deg, double roll_deg) {
  const double p = pitch_deg * kDeg, y = yaw_deg * kDeg, r = roll_deg * kDeg;
  const double cp = std::cos(p), sp = std::sin(p), cy = std::cos(y), sy = std::sin(y);
  const double cr = std::cos(r), sr = std::sin(r);
  Mat3 R;
  R << cp * cy, cy * sp * sr - sy * cr, -cy * sp * cr - sy * sr,  //
      cp * sy, sy * sp * sr + cy * cr, -sy * sp * cr + cy * sr,   //
      sp, -cp * sr, cp * cr;
  return R;
}

Vec3 pyr_from_rotation(const Mat3& R) {
  const double cp = std::hypot(R(0, 0), R(1, 0));  // |cos pitch| >= 0
  const double pitch = std::atan2(R(2, 0), cp);
  double yaw, roll;
  if (cp > 1e-12) {
    yaw = std::atan2(R(1, 0), R(0, 0));
    roll = std::atan2(-R(2, 1), R(2, 2));
  } else {  // gimbal lock: only yaw -/+ roll is defined; put it all in yaw
    roll = 0.0;
    yaw = std::atan2(-R(0, 1), R(1, 1));
  }
  return Vec3(pitch * kRad, yaw * kRad, roll * kRad);
}

Transform transform_from_array(const double* a) {
  return Transform{rotation_from_pyr(a[3], a[4], a[5]), Vec3(a[0], a[1], a[2])};
}

void transform_to_array(const Transform& t, double* a) {
  const Vec3 e = pyr_from_rotation(t.R);
  a[0] = t.t.x(), a[1] = t.t.y(), a[2] = t.t.z();
  a[3] = e.x(), a[4] = e.y(), a[5] = e.z();
}

void rotation_matrices(const double* pyr, double* R, std::size_t n) {
  parallel_for(n, kMinBlock, [&](std::size_t lo, std::size_t hi) {
    for (std::size_t i = lo; i < hi; ++i) {
      const double* e = pyr + 3 * i;
      // Eigen is column-major; store row-major for NumPy.
      Eigen::Map<Eigen::Matrix<double, 3, 3, Eigen::RowMajor>>(R + 9 * i) =
          rotation_from_pyr(e[0], e[1], e[2]);
    }
  });
}

void rotations_to_euler(const double* R, double* pyr, std::size_t n) {
  parallel_for(n, kMinBlock, [&](std::size_t lo, std::size_t hi) {
    for (std::size_t i = lo; i < hi; ++i) {
      const Mat3 m = Eigen::Map<const Eigen::Matrix<double, 3, 3, Eigen::RowMajor>>(R + 9 * i);
      Eigen::Map<Vec3>(pyr + 3 * i) = pyr_from_rotation(m);
    }
  });
}

void compose_batch(const double* a, std::size_t ka, const double* b, std::size_t kb,
                   double* out, std::size_t n) {
  parallel_for(n, kMinBlock, [&](std::size_t lo, std::size_t hi) {
    for (std::size_t i = lo; i < hi; ++i) {
      transform_to_array(compose(transform_from_array(a + 6 * (i / ka)),
                                 transform_from_array(b + 6 * (i / kb))),
                         out + 6 * i);
    }
  });
}

void invert_batch(const double* t, double* out, std::size_t n) {
  parallel_for(n, kMinBlock, [&](std::size_t lo, std::size_t hi) {
    for (std::size_t i = lo; i < hi; ++i)
      transform_to_array(inverse(transform_from_array(t + 6 * i)), out + 6 * i);
  });
}

void transform_points_batch(const double* t, std::size_t kt, const double* p, std::size_t kp,
                            double* out, std::size_t n) {
  parallel_for(n, kMinBlock, [&](std::size_t lo, std::size_t hi) {
    std::size_t cached = SIZE_MAX;
    Transform T;
    for (std::size_t i = lo; i < hi; ++i) {
      const std::size_t ti = i / kt;
      if (ti != cached) T = transform_from_array(t + 6 * ti), cached = ti;
      Eigen::Map<Vec3>(out + 3 * i) = T.R * Eigen::Map<const Vec3>(p + 3 * (i / kp)) + T.t;
    }
  });
}

void check_parents(const std::int32_t* parents, std::size_t joints) {
  if (joints == 0) throw std::invalid_argument("parents: the skeleton has no joints");
  if (parents[0] != -1)
    throw std::invalid_argument("parents[0] must be -1 (joint 0 is the root), got " +
                                std::to_string(parents[0]));
  for (std::size_t j = 1; j < joints; ++j)
    if (parents[j] < 0 || static_cast<std::size_t>(parents[j]) >= j)
      throw std::invalid_argument("parents[" + std::to_string(j) + "] = " +
                                  std::to_string(parents[j]) +
                                  ": every parent must come before its child (0 <= parent < j)");
}

void forward_kinematics(const double* relative, std::size_t frames, std::size_t joints,
                        const std::int32_t* parents, const double* root, std::size_t kr,
                        double* out) {
  check_parents(parents, joints);
  parallel_for(frames, kMinBlock / joints + 1, [&](std::size_t lo, std::size_t hi) {
    std::vector<Transform> A(joints);
    for (std::size_t f = lo; f < hi; ++f) {
      const double* rel = relative + f * joints * 6;
      double* o = out + f * joints * 6;
      const Transform first = transform_from_array(rel);
      A[0] = root ? compose(transform_from_array(root + 6 * (f / kr)), first) : first;
      transform_to_array(A[0], o);
      for (std::size_t j = 1; j < joints; ++j) {
        A[j] = compose(A[static_cast<std::size_t>(parents[j])], transform_from_array(rel + 6 * j));
        transform_to_array(A[j], o + 6 * j);
      }
    }
  });
}

}  // namespace bsp
