#include "bsp/geometry/kinematics.hpp"

#include <cmath>
#include <stdexcept>
#include <string>

#include <array>
#include <cstdlib>
#include <memory>

#include "bsp/common/parallel.hpp"
#include "trig_simd.hpp"

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

namespace {

// Scratch space for block-wise vector trig. Blocks are padded to a multiple of 8 values
// and 64-byte aligned, so the vector loops have no scalar head or tail: every element is
// computed by the same instruction sequence wherever it sits, and results do not depend
// on how work is split between threads.
class Scratch {
 public:
  explicit Scratch(std::size_t rotations) : cap_(round_up(rotations)) {
    for (auto& b : bufs_) b.reset(static_cast<double*>(std::aligned_alloc(64, 3 * cap_ * sizeof(double))));
    mats_.resize(9 * cap_);
  }
  static std::size_t round_up(std::size_t n) { return (n + 7) / 8 * 8; }
  std::size_t capacity() const { return cap_; }
  double* buf(int i) { return bufs_[static_cast<std::size_t>(i)].get(); }
  double* mats() { return mats_.data(); }

 private:
  struct Free {
    void operator()(double* p) const noexcept { std::free(p); }
  };
  std::size_t cap_;
  std::array<std::unique_ptr<double[], Free>, 3> bufs_;
  std::vector<double> mats_;
};

// R (row-major 3x3 each) of n <= capacity rotations whose angles sit at pyr + stride * i.
void matrices_from_pyr(const double* pyr, std::size_t stride, std::size_t n, double* R, Scratch& s) {
  const std::size_t np = Scratch::round_up(n);
  double *deg = s.buf(0), *sn = s.buf(1), *cs = s.buf(2);
  for (std::size_t i = 0; i < n; ++i)
    for (int k = 0; k < 3; ++k) deg[3 * i + k] = pyr[stride * i + k];
  std::fill(deg + 3 * n, deg + 3 * np, 0.0);
  simd::sincos_deg(deg, sn, cs, 3 * np);
  for (std::size_t i = 0; i < n; ++i) {
    const double sp = sn[3 * i], cp = cs[3 * i], sy = sn[3 * i + 1], cy = cs[3 * i + 1];
    const double sr = sn[3 * i + 2], cr = cs[3 * i + 2];
    double* m = R + 9 * i;
    m[0] = cp * cy, m[1] = cy * sp * sr - sy * cr, m[2] = -cy * sp * cr - sy * sr;
    m[3] = cp * sy, m[4] = sy * sp * sr + cy * cr, m[5] = -sy * sp * cr + cy * sr;
    m[6] = sp, m[7] = -cp * sr, m[8] = cp * cr;
  }
}

// Angles of n <= capacity row-major matrices, written to pyr + stride * i.
void pyr_from_matrices(const double* R, std::size_t n, double* pyr, std::size_t stride, Scratch& s) {
  const std::size_t np = Scratch::round_up(n);
  double *y = s.buf(0), *x = s.buf(1), *out = s.buf(2);
  for (std::size_t i = 0; i < n; ++i) {
    const double* m = R + 9 * i;
    y[3 * i] = m[6], x[3 * i] = std::sqrt(m[0] * m[0] + m[3] * m[3]);
    y[3 * i + 1] = m[3], x[3 * i + 1] = m[0];
    y[3 * i + 2] = -m[7], x[3 * i + 2] = m[8];
  }
  std::fill(y + 3 * n, y + 3 * np, 0.0);
  std::fill(x + 3 * n, x + 3 * np, 1.0);
  simd::atan2_deg(y, x, out, 3 * np);
  for (std::size_t i = 0; i < n; ++i) {
    double* e = pyr + stride * i;
    if (x[3 * i] > 1e-12) {
      e[0] = out[3 * i], e[1] = out[3 * i + 1], e[2] = out[3 * i + 2];
    } else {  // gimbal lock: the scalar path's convention (roll 0)
      const Mat3 m = Eigen::Map<const Eigen::Matrix<double, 3, 3, Eigen::RowMajor>>(R + 9 * i);
      const Vec3 v = pyr_from_rotation(m);
      e[0] = v.x(), e[1] = v.y(), e[2] = v.z();
    }
  }
}

constexpr std::size_t kBlockRot = 512;

using RowMat = Eigen::Matrix<double, 3, 3, Eigen::RowMajor>;

}  // namespace

void rotation_matrices(const double* pyr, double* R, std::size_t n) {
  parallel_for(n, kMinBlock, [&](std::size_t lo, std::size_t hi) {
    Scratch s(kBlockRot);
    for (std::size_t b = lo; b < hi; b += kBlockRot)
      matrices_from_pyr(pyr + 3 * b, 3, std::min(kBlockRot, hi - b), R + 9 * b, s);
  });
}

void rotations_to_euler(const double* R, double* pyr, std::size_t n) {
  parallel_for(n, kMinBlock, [&](std::size_t lo, std::size_t hi) {
    Scratch s(kBlockRot);
    for (std::size_t b = lo; b < hi; b += kBlockRot)
      pyr_from_matrices(R + 9 * b, std::min(kBlockRot, hi - b), pyr + 3 * b, 3, s);
  });
}

void compose_batch(const double* a, std::size_t ka, const double* b, std::size_t kb,
                   double* out, std::size_t n) {
  parallel_for(n, kMinBlock, [&](std::size_t lo, std::size_t hi) {
    Scratch s(kBlockRot);
    std::vector<double> ra(9 * kBlockRot), rb(9 * kBlockRot), ta(3 * kBlockRot), pa(6 * kBlockRot), pb(6 * kBlockRot);
    for (std::size_t b0 = lo; b0 < hi; b0 += kBlockRot) {
      const std::size_t m = std::min(kBlockRot, hi - b0);
      for (std::size_t i = 0; i < m; ++i) {
        std::copy_n(a + 6 * ((b0 + i) / ka), 6, &pa[6 * i]);
        std::copy_n(b + 6 * ((b0 + i) / kb), 6, &pb[6 * i]);
      }
      matrices_from_pyr(pa.data() + 3, 6, m, ra.data(), s);
      matrices_from_pyr(pb.data() + 3, 6, m, rb.data(), s);
      double* R = s.mats();
      for (std::size_t i = 0; i < m; ++i) {
        const Eigen::Map<const RowMat> A(&ra[9 * i]), B(&rb[9 * i]);
        Eigen::Map<RowMat>(R + 9 * i) = A * B;
        Eigen::Map<Vec3>(out + 6 * (b0 + i)) = A * Eigen::Map<const Vec3>(&pb[6 * i]) + Eigen::Map<const Vec3>(&pa[6 * i]);
      }
      pyr_from_matrices(R, m, out + 6 * b0 + 3, 6, s);
    }
  });
}

void invert_batch(const double* t, double* out, std::size_t n) {
  parallel_for(n, kMinBlock, [&](std::size_t lo, std::size_t hi) {
    Scratch s(kBlockRot);
    std::vector<double> r(9 * kBlockRot);
    for (std::size_t b0 = lo; b0 < hi; b0 += kBlockRot) {
      const std::size_t m = std::min(kBlockRot, hi - b0);
      matrices_from_pyr(t + 6 * b0 + 3, 6, m, r.data(), s);
      double* R = s.mats();
      for (std::size_t i = 0; i < m; ++i) {
        const Eigen::Map<const RowMat> A(&r[9 * i]);
        Eigen::Map<RowMat>(R + 9 * i) = A.transpose();
        Eigen::Map<Vec3>(out + 6 * (b0 + i)) = -(A.transpose() * Eigen::Map<const Vec3>(t + 6 * (b0 + i)));
      }
      pyr_from_matrices(R, m, out + 6 * b0 + 3, 6, s);
    }
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
  const std::size_t fpb = std::max<std::size_t>(1, kBlockRot / joints);  // frames per block
  parallel_for(frames, kMinBlock / joints + 1, [&](std::size_t lo, std::size_t hi) {
    Scratch s(fpb * joints);
    std::vector<double> rel_R(9 * fpb * joints);
    for (std::size_t f0 = lo; f0 < hi; f0 += fpb) {
      const std::size_t nf = std::min(fpb, hi - f0), nr = nf * joints;
      const double* rel = relative + f0 * joints * 6;
      double* o = out + f0 * joints * 6;
      matrices_from_pyr(rel + 3, 6, nr, rel_R.data(), s);
      double* A = s.mats();
      for (std::size_t f = 0; f < nf; ++f) {
        const std::size_t base = f * joints;
        const Eigen::Map<const RowMat> R0(&rel_R[9 * base]);
        const Eigen::Map<const Vec3> t0(rel + 6 * base);
        if (root) {
          const Transform M = transform_from_array(root + 6 * ((f0 + f) / kr));
          Eigen::Map<RowMat>(A + 9 * base) = M.R * R0;
          Eigen::Map<Vec3>(o + 6 * base) = M.R * t0 + M.t;
        } else {
          Eigen::Map<RowMat>(A + 9 * base) = R0;
          Eigen::Map<Vec3>(o + 6 * base) = t0;
        }
        for (std::size_t j = 1; j < joints; ++j) {
          const std::size_t p = base + static_cast<std::size_t>(parents[j]), c = base + j;
          const Eigen::Map<const RowMat> Ap(A + 9 * p);
          Eigen::Map<RowMat>(A + 9 * c) = Ap * Eigen::Map<const RowMat>(&rel_R[9 * c]);
          Eigen::Map<Vec3>(o + 6 * c) = Ap * Eigen::Map<const Vec3>(rel + 6 * c) + Eigen::Map<const Vec3>(o + 6 * p);
        }
      }
      pyr_from_matrices(A, nr, o + 3, 6, s);
    }
  });
}

}  // namespace bsp
