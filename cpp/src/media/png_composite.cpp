// APNG blend_op OVER. SOURCE is a plain copy and needs no helper.
#include <cstring>

#include "png.hpp"

namespace bsp::png {
namespace {
// x / 255 rounded, exact for x <= 255 * 255 (FFmpeg's FAST_DIV255).
inline unsigned div255(unsigned x) { return ((x + 128) * 257) >> 16; }
}  // namespace

void blend_over_alpha(std::uint8_t* dst, const std::uint8_t* src, std::size_t n,
                      std::size_t channels) {
  const std::size_t a = channels - 1;
  for (std::size_t i = 0; i < n; ++i, dst += channels, src += channels) {
    const unsigned fa = src[a], ba = dst[a];
    if (fa == 255) {
      std::memcpy(dst, src, channels);
      continue;
    }
    if (fa == 0) continue;
    const unsigned oa = fa + div255((255 - fa) * ba);  // > 0 because fa > 0
    for (std::size_t c = 0; c < a; ++c) {
      const unsigned v = ba == 255
                             ? div255(fa * src[c] + (255 - fa) * dst[c])
                             : (255 * fa * src[c] + (255 - fa) * ba * dst[c]) / (255 * oa);
      dst[c] = static_cast<std::uint8_t>(v);
    }
    dst[a] = static_cast<std::uint8_t>(oa);
  }
}

void blend_over_palette(std::uint8_t* dst, const std::uint8_t* src, std::size_t n,
                        const std::uint8_t* alpha256) {
  for (std::size_t i = 0; i < n; ++i)
    if (alpha256[src[i]] != 0) dst[i] = src[i];
}

void blend_over_key(std::uint8_t* dst, const std::uint8_t* src, std::size_t n,
                    std::size_t channels, const std::uint8_t* key) {
  for (std::size_t i = 0; i < n; ++i, dst += channels, src += channels)
    if (std::memcmp(src, key, channels) != 0) std::memcpy(dst, src, channels);
}

}  // namespace bsp::png
