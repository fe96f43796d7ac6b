// Vectorised trigonometry over flat arrays (see trig_simd.cpp).
#pragma once
#include <cstddef>

namespace bsp::simd {
// s[i] = sin(deg[i] degrees), c[i] = cos(...).
void sincos_deg(const double* deg, double* s, double* c, std::size_t n);
// out[i] = atan2(y[i], x[i]) in degrees.
void atan2_deg(const double* y, const double* x, double* out, std::size_t n);
}  // namespace bsp::simd
