// PNG building blocks shared by the APNG writer and reader: big-endian integers, chunk CRCs,
// the five row filters and RAII for libdeflate (the only compression library we use).
#pragma once
#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <utility>
#include <vector>

struct libdeflate_compressor;
struct libdeflate_decompressor;

namespace bsp::png {

inline constexpr std::uint8_t kSignature[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};

inline std::uint32_t get_u32(const std::uint8_t* p) {
  return (std::uint32_t{p[0]} << 24) | (std::uint32_t{p[1]} << 16) | (std::uint32_t{p[2]} << 8) |
         std::uint32_t{p[3]};
}
inline std::uint16_t get_u16(const std::uint8_t* p) {
  return static_cast<std::uint16_t>((p[0] << 8) | p[1]);
}
inline void put_u32(std::uint8_t* p, std::uint32_t v) {
  p[0] = static_cast<std::uint8_t>(v >> 24);
  p[1] = static_cast<std::uint8_t>(v >> 16);
  p[2] = static_cast<std::uint8_t>(v >> 8);
  p[3] = static_cast<std::uint8_t>(v);
}
inline void put_u16(std::uint8_t* p, std::uint16_t v) {
  p[0] = static_cast<std::uint8_t>(v >> 8);
  p[1] = static_cast<std::uint8_t>(v);
}

// CRC-32 of a chunk: over its 4-byte type followed by its data (not the length).
std::uint32_t chunk_crc(const std::uint8_t* type, const std::uint8_t* data, std::size_t size);

// fcTL dispose_op and blend_op values.
enum : std::uint8_t { kDisposeNone = 0, kDisposeBackground = 1, kDisposePrevious = 2 };
enum : std::uint8_t { kBlendSource = 0, kBlendOver = 1 };

// One APNG frame (fcTL), or the single image of a plain PNG.
struct FrameInfo {
  std::uint32_t x = 0, y = 0, w = 0, h = 0;
  std::uint16_t delay_num = 0, delay_den = 100;  // a den of 0 is stored as 100 (APNG spec)
  std::uint8_t dispose = kDisposeNone, blend = kBlendSource;
  std::vector<std::pair<std::size_t, std::size_t>> data;  // zlib pieces: (offset, size)
};

// What the chunk walk learns about a file.
// Limits of the reader: larger headers are refused before anything is allocated.
inline constexpr std::uint32_t kMaxSide = 16384;
inline constexpr std::uint64_t kMaxPixels = std::uint64_t{1} << 26;  // 8192 x 8192
inline constexpr std::int64_t kMaxFrames = 10'000'000;

struct FileIndex {
  std::uint32_t width = 0, height = 0;
  int colour_type = 0;
  std::size_t channels = 1;            // bytes per pixel (8-bit samples)
  std::vector<std::uint8_t> palette;   // PLTE, RGB triplets
  std::uint8_t palette_alpha[256];     // tRNS for palette files (255 = opaque)
  std::uint8_t key[4] = {0};           // tRNS colour key of grey/RGB files
  bool has_key = false, has_trns = false;
  std::vector<FrameInfo> frames;
  std::int64_t declared = -1;   // acTL num_frames (1 for a plain PNG)
  std::int64_t bad_frame = -1;  // first frame that cannot be decoded, -1 = none
  std::string bad_reason;
  FileIndex() { std::fill(palette_alpha, palette_alpha + 256, std::uint8_t{255}); }
};

// Walks the chunks of the PNG/APNG `file` (read from `path`, used in messages). Damage
// before the first frame's data throws ApngError; later damage (bad CRC, truncation,
// sequence errors, bad fcTL) is recorded in bad_frame/bad_reason against the frame it
// belongs to, so the frames before it stay readable.
FileIndex index_png(const std::vector<std::uint8_t>& file, const std::string& path);

enum Filter : std::uint8_t { kNone = 0, kSub = 1, kUp = 2, kAverage = 3, kPaeth = 4 };

// Reverses filter `type` on one row of `len` bytes in place. `prev` is the previous
// unfiltered row, or null for the first row of an image (PNG treats it as zeros); `bpp` is
// bytes per complete pixel (>= 1). Returns false for an unknown filter type.
bool unfilter_row(std::uint8_t type, std::uint8_t* row, const std::uint8_t* prev, std::size_t len,
                  std::size_t bpp);

// Applies filter `type` to `row` (prev as above) and writes the filtered bytes to `out`.
void filter_row(std::uint8_t type, const std::uint8_t* row, const std::uint8_t* prev,
                std::size_t len, std::size_t bpp, std::uint8_t* out);

// The writer's cheap filter choice for indexed rows: Up when the row above is mostly equal
// (long runs of zeros deflate best), None otherwise. See choose_filter's comment for the
// measurements behind it.
std::uint8_t choose_filter(const std::uint8_t* row, const std::uint8_t* prev, std::size_t len);

// APNG blend_op OVER for one row of `n` pixels, destination `dst` updated in place.
// With an alpha channel (`channels` bytes per pixel, alpha last): Porter-Duff "over" with
// FFmpeg's rounding, so results equal FFmpeg's APNG decoder bit for bit.
void blend_over_alpha(std::uint8_t* dst, const std::uint8_t* src, std::size_t n,
                      std::size_t channels);
// Palette indices with a tRNS alpha table: a fully transparent source index keeps the
// canvas; any other index replaces it (indices cannot be mixed).
void blend_over_palette(std::uint8_t* dst, const std::uint8_t* src, std::size_t n,
                        const std::uint8_t* alpha256);
// Grey or RGB with a tRNS colour key: source pixels equal to `key` keep the canvas.
void blend_over_key(std::uint8_t* dst, const std::uint8_t* src, std::size_t n,
                    std::size_t channels, const std::uint8_t* key);

struct CompressorDeleter {
  void operator()(libdeflate_compressor* p) const noexcept;
};
struct DecompressorDeleter {
  void operator()(libdeflate_decompressor* p) const noexcept;
};
using Compressor = std::unique_ptr<libdeflate_compressor, CompressorDeleter>;
using Decompressor = std::unique_ptr<libdeflate_decompressor, DecompressorDeleter>;

// Null on allocation failure (callers throw their own typed error naming the file).
Compressor make_compressor(int level);
Decompressor make_decompressor();

}  // namespace bsp::png
