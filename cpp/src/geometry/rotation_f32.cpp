// Float32 rotation matrices of many transforms, bitwise equal to the scalar path.
//
// The conversion writes static_cast<float>(rotation_from_pyr(...)) for every joint of every
// frame; libm's sin and cos took ~11 % of its CPU time. Here the sines and cosines come
// from libmvec's vector sin/cos (simd::sin_cos_deg_vector), which are not bitwise equal to
// libm's, so every matrix entry is checked before it is written:
//  * each vector sine or cosine lies within a relative kFactorError = 2^-44 of libm's
//    (tested in test_geometry.cpp, near multiples of 90 degrees too; measured: 2^-51), and
//    is exactly libm's (+-0, 1) for an angle of +-0, set here rather than trusted;
//  * an entry is a sum of at most two products of at most three such factors, so it lies
//    within (3 * 2^-44 + 6 * 2^-53) * T < 2^-42 * T of the scalar path's entry, T being the
//    sum of the terms' magnitudes; with the bound 2^-41 * T (T as computed here), when
//    v - bound and v + bound round to the same float (bit for bit), so does the scalar
//    entry (rounding is monotone), and that float is written. T = 0 means exact factors
//    and the scalar path's very operations: the same bits.
// Otherwise (near a float rounding boundary: one matrix in 3,000 to 8,000 on random angles)
// and for angles that are not finite or beyond 1e6 degrees, rotation_from_pyr itself gives
// the matrix. The output therefore never depends on libmvec's rounding.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>

#include "bsp/geometry/kinematics.hpp"
#include "trig_simd.hpp"

namespace bsp {
namespace {

constexpr double kEntryBound = 0x1p-41;  // relative to the entry's terms (see above)
constexpr double kMaxDegrees = 1e6;
constexpr double kDeg = M_PI / 180.0;
constexpr std::size_t kChunk = 64;  // rotations per vector call
constexpr bool kTwoTerms[9] = {false, true, true, false, true, true, false, false, false};

void scalar_matrix(const double* pyr, float* out) {
  const Mat3 R = rotation_from_pyr(pyr[0], pyr[1], pyr[2]);
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) out[3 * r + c] = static_cast<float>(R(r, c));
}

std::uint32_t bits(float f) {
  std::uint32_t u;
  std::memcpy(&u, &f, sizeof u);
  return u;
}

// True (and out filled) when every entry's float is certain.
bool checked_matrix(const double* sn, const double* cs, float* out) {
  const double sp = sn[0], cp = cs[0], sy = sn[1], cy = cs[1], sr = sn[2], cr = cs[2];
  // The products of rotation_from_pyr, in its order: entry k = p[k] + q[k].
  const double p[9] = {cp * cy, cy * sp * sr, -cy * sp * cr, cp * sy, sy * sp * sr,
                       -sy * sp * cr, sp, -cp * sr, cp * cr};
  const double q[9] = {0, -(sy * cr), -(sy * sr), 0, cy * cr, cy * sr, 0, 0, 0};
  for (int k = 0; k < 9; ++k) {
    const double v = kTwoTerms[k] ? p[k] + q[k] : p[k];  // x - y is x + (-y), bit for bit
    const double bound = (std::fabs(p[k]) + std::fabs(q[k])) * kEntryBound;
    out[k] = static_cast<float>(v);
    if (bound == 0) continue;  // exact factors: the scalar path's bits
    if (bits(static_cast<float>(v - bound)) != bits(static_cast<float>(v + bound)))
      return false;  // also for NaN
  }
  return true;
}

}  // namespace

void rotation_matrices_f32(const float* t, std::size_t stride, std::size_t n, float* R) {
  double deg[3 * kChunk], sn[3 * kChunk], cs[3 * kChunk];
  for (std::size_t i0 = 0; i0 < n; i0 += kChunk) {
    const std::size_t m = std::min(kChunk, n - i0);
    for (std::size_t i = 0; i < m; ++i)
      for (std::size_t k = 0; k < 3; ++k) deg[3 * i + k] = t[stride * (i0 + i) + 3 + k];
    simd::sin_cos_deg_vector(deg, sn, cs, 3 * m);
    for (std::size_t k = 0; k < 3 * m; ++k)
      if (deg[k] == 0) sn[k] = deg[k] * kDeg, cs[k] = 1.0;  // libm's sin(+-0), cos(+-0)
    for (std::size_t i = 0; i < m; ++i) {
      const double* a = deg + 3 * i;
      float* out = R + 9 * (i0 + i);
      const bool in_range = std::fabs(a[0]) <= kMaxDegrees && std::fabs(a[1]) <= kMaxDegrees &&
                            std::fabs(a[2]) <= kMaxDegrees;  // false for NaN
      if (!in_range || !checked_matrix(sn + 3 * i, cs + 3 * i, out)) scalar_matrix(a, out);
    }
  }
}

}  // namespace bsp
