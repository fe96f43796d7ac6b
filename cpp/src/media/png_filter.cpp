// PNG row filters (PNG spec section 9), CRCs and libdeflate handles.
#include <libdeflate.h>

#include <algorithm>
#include <cstdlib>
#include <cstring>

#include "png.hpp"

namespace bsp::png {
namespace {

inline std::uint8_t paeth(int a, int b, int c) {
  const int p = a + b - c;
  const int pa = std::abs(p - a), pb = std::abs(p - b), pc = std::abs(p - c);
  if (pa <= pb && pa <= pc) return static_cast<std::uint8_t>(a);
  return static_cast<std::uint8_t>(pb <= pc ? b : c);
}

// Each unfilter adds the prediction from already-reconstructed bytes; the first `bpp`
// bytes of a row have no left neighbour (a = c = 0).
void unfilter_sub(std::uint8_t* row, std::size_t len, std::size_t bpp) {
  for (std::size_t i = bpp; i < len; ++i) row[i] = static_cast<std::uint8_t>(row[i] + row[i - bpp]);
}
void unfilter_up(std::uint8_t* row, const std::uint8_t* prev, std::size_t len) {
  for (std::size_t i = 0; i < len; ++i) row[i] = static_cast<std::uint8_t>(row[i] + prev[i]);
}
void unfilter_average(std::uint8_t* row, const std::uint8_t* prev, std::size_t len,
                      std::size_t bpp) {
  for (std::size_t i = 0; i < len; ++i) {
    const unsigned a = i >= bpp ? row[i - bpp] : 0u, b = prev ? prev[i] : 0u;
    row[i] = static_cast<std::uint8_t>(row[i] + ((a + b) >> 1));
  }
}
void unfilter_paeth(std::uint8_t* row, const std::uint8_t* prev, std::size_t len,
                    std::size_t bpp) {
  if (!prev) return unfilter_sub(row, len, bpp);  // Paeth with b = c = 0 predicts a
  for (std::size_t i = 0; i < bpp && i < len; ++i)
    row[i] = static_cast<std::uint8_t>(row[i] + prev[i]);  // a = c = 0 predicts b
  for (std::size_t i = bpp; i < len; ++i)
    row[i] = static_cast<std::uint8_t>(row[i] + paeth(row[i - bpp], prev[i], prev[i - bpp]));
}

}  // namespace

std::uint32_t chunk_crc(const std::uint8_t* type, const std::uint8_t* data, std::size_t size) {
  const std::uint32_t crc = libdeflate_crc32(0, type, 4);
  return size ? libdeflate_crc32(crc, data, size) : crc;
}

bool unfilter_row(std::uint8_t type, std::uint8_t* row, const std::uint8_t* prev, std::size_t len,
                  std::size_t bpp) {
  switch (type) {
    case kNone: return true;
    case kSub: unfilter_sub(row, len, bpp); return true;
    case kUp:
      if (prev) unfilter_up(row, prev, len);
      return true;
    case kAverage: unfilter_average(row, prev, len, bpp); return true;
    case kPaeth: unfilter_paeth(row, prev, len, bpp); return true;
    default: return false;
  }
}

void filter_row(std::uint8_t type, const std::uint8_t* row, const std::uint8_t* prev,
                std::size_t len, std::size_t bpp, std::uint8_t* out) {
  // One loop per type (not a switch per byte): None and Up then vectorise.
  const std::size_t head = std::min(bpp, len);
  if (type == kUp && prev) {
    for (std::size_t i = 0; i < len; ++i) out[i] = static_cast<std::uint8_t>(row[i] - prev[i]);
  } else if (type == kSub || (type == kPaeth && !prev)) {
    std::memcpy(out, row, head);
    for (std::size_t i = bpp; i < len; ++i)
      out[i] = static_cast<std::uint8_t>(row[i] - row[i - bpp]);
  } else if (type == kAverage) {
    for (std::size_t i = 0; i < len; ++i) {
      const unsigned a = i >= bpp ? row[i - bpp] : 0u, b = prev ? prev[i] : 0u;
      out[i] = static_cast<std::uint8_t>(row[i] - ((a + b) >> 1));
    }
  } else if (type == kPaeth) {
    for (std::size_t i = 0; i < head; ++i) out[i] = static_cast<std::uint8_t>(row[i] - prev[i]);
    for (std::size_t i = bpp; i < len; ++i)
      out[i] = static_cast<std::uint8_t>(row[i] - paeth(row[i - bpp], prev[i], prev[i - bpp]));
  } else {
    std::memcpy(out, row, len);  // None, or Up of a first row
  }
}

// Measured on a synthetic 1600x600 street segmentation frame with libdeflate level 6:
// None 11.7 KB, Sub 11.5 KB, Up 9.5 KB, Paeth 9.4 KB, per-row minimum-sum-of-absolute-
// differences 9.37 KB but 2.5 ms of filtering per frame, this rule 9.48 KB in 0.17 ms
// (deflate itself takes 2.8 ms). Level 9 would save another 6 % for 3.7x the deflate time.
std::uint8_t choose_filter(const std::uint8_t* row, const std::uint8_t* prev, std::size_t len) {
  if (!prev) return kNone;
  std::size_t same = 0;
  for (std::size_t i = 0; i < len; ++i) same += row[i] == prev[i];
  return same * 2 >= len ? kUp : kNone;
}

void CompressorDeleter::operator()(libdeflate_compressor* p) const noexcept {
  libdeflate_free_compressor(p);
}
void DecompressorDeleter::operator()(libdeflate_decompressor* p) const noexcept {
  libdeflate_free_decompressor(p);
}
Compressor make_compressor(int level) { return Compressor(libdeflate_alloc_compressor(level)); }
Decompressor make_decompressor() { return Decompressor(libdeflate_alloc_decompressor()); }

}  // namespace bsp::png
