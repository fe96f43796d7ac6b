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
constexpr std::size_t kChunk = 64;  // rotations per vector call

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

// Entry v (terms of magnitudes summing to `terms`) as a float; returns non-zero when that
// float is not certain. terms 0: exact factors and the scalar path's very operations,
// hence its bits.
[[gnu::always_inline]] inline std::uint32_t entry(double v, double terms, float& out) {
  const double bound = terms * kEntryBound;
  out = static_cast<float>(v);
  const std::uint32_t differ =
      bits(static_cast<float>(v - bound)) ^ bits(static_cast<float>(v + bound));
  return differ & (0u - static_cast<std::uint32_t>(bound != 0));
}

// s, c = a, 1 when a is +-0, else sn, cs; branch-free (bit masks: GCC if-converts no
// chain of three `a == 0 ? ...` selects).
[[gnu::always_inline]] inline void exact_at_zero(double a, double sn, double cs, double& s,
                                                 double& c) {
  std::uint64_t ua, us, uc, one;
  const double kOne = 1.0;
  std::memcpy(&ua, &a, 8), std::memcpy(&us, &sn, 8), std::memcpy(&uc, &cs, 8);
  std::memcpy(&one, &kOne, 8);
  const std::uint64_t zero = 0 - static_cast<std::uint64_t>(a == 0);
  us = (ua & zero) | (us & ~zero), uc = (one & zero) | (uc & ~zero);
  std::memcpy(&s, &us, 8), std::memcpy(&c, &uc, 8);
}

// One chunk of m <= kChunk rotations, structure of arrays: angle j of rotation i at
// sn[j][i], cs[j][i]. The loop holds no branch (whether a float is certain is data, and
// mispredicted branches were half the cost), so GCC vectorises it; target_clones adds an
// AVX2 copy (AVX2 alone, no FMA: every operation stays one IEEE operation, so the bits do
// not depend on the copy that runs). unsure[i] != 0: rotation i needs the scalar path (so
// does one whose angles are not finite or beyond kMaxDegrees, checked by the caller).
__attribute__((target_clones("avx2", "default")))
void chunk_matrices(const double (*deg)[kChunk], const double (*sn)[kChunk],
                    const double (*cs)[kChunk], std::size_t m, float (*out)[kChunk],
                    std::uint32_t* unsure) {
  for (std::size_t i = 0; i < m; ++i) {
    // For an angle of +-0, libm's sin(+-0) = +-0 and cos(+-0) = 1, exactly.
    double sp, cp, sy, cy, sr, cr;
    exact_at_zero(deg[0][i], sn[0][i], cs[0][i], sp, cp);
    exact_at_zero(deg[1][i], sn[1][i], cs[1][i], sy, cy);
    exact_at_zero(deg[2][i], sn[2][i], cs[2][i], sr, cr);
    // The operations of rotation_from_pyr, in its order (x - y is x + (-y), bit for bit).
    const double p1 = cy * sp * sr, q1 = -(sy * cr), p2 = -cy * sp * cr, q2 = -(sy * sr);
    const double p4 = sy * sp * sr, q4 = cy * cr, p5 = -sy * sp * cr, q5 = cy * sr;
    const double m0 = cp * cy, m3 = cp * sy, m7 = -cp * sr, m8 = cp * cr;
    using std::fabs;
    unsure[i] = entry(m0, fabs(m0), out[0][i]) |
                entry(p1 + q1, fabs(p1) + fabs(q1), out[1][i]) |
                entry(p2 + q2, fabs(p2) + fabs(q2), out[2][i]) |
                entry(m3, fabs(m3), out[3][i]) |
                entry(p4 + q4, fabs(p4) + fabs(q4), out[4][i]) |
                entry(p5 + q5, fabs(p5) + fabs(q5), out[5][i]) |
                entry(sp, fabs(sp), out[6][i]) |
                entry(m7, fabs(m7), out[7][i]) |
                entry(m8, fabs(m8), out[8][i]);
  }
}

}  // namespace

void rotation_matrices_f32(const float* t, std::size_t stride, std::size_t n, float* R) {
  double deg[3][kChunk], sn[3][kChunk], cs[3][kChunk];
  float out[9][kChunk];
  std::uint32_t unsure[kChunk];
  for (std::size_t i0 = 0; i0 < n; i0 += kChunk) {
    const std::size_t m = std::min(kChunk, n - i0);
    for (std::size_t i = 0; i < m; ++i)
      for (std::size_t j = 0; j < 3; ++j) deg[j][i] = t[stride * (i0 + i) + 3 + j];
    for (std::size_t j = 0; j < 3; ++j) simd::sin_cos_deg_vector(deg[j], sn[j], cs[j], m);
    chunk_matrices(deg, sn, cs, m, out, unsure);
    for (std::size_t i = 0; i < m; ++i) {
      float* o = R + 9 * (i0 + i);
      const double a[3] = {deg[0][i], deg[1][i], deg[2][i]};
      const bool in_range = std::fabs(a[0]) <= kMaxDegrees && std::fabs(a[1]) <= kMaxDegrees &&
                            std::fabs(a[2]) <= kMaxDegrees;  // false for NaN
      if (in_range && unsure[i] == 0) {
        for (int k = 0; k < 9; ++k) o[k] = out[k][i];
      } else {
        scalar_matrix(a, o);
      }
    }
  }
}

}  // namespace bsp
