// ApngWriter: palette-indexed APNG with changed-rectangle frames, written as it goes.
#include <libdeflate.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <tuple>
#include <utility>

#include "bsp/common/errors.hpp"
#include "bsp/media/apng.hpp"
#include "common/atomic_file.hpp"
#include "png.hpp"

namespace bsp {

const std::array<const char*, kNumTags> kTagNames = {
    "Unlabeled", "Building", "Fence",    "Other",     "Pedestrian", "Pole",
    "RoadLine",  "Road",     "Sidewalk", "Vegetation", "Vehicle",   "Wall",
    "TrafficSign", "Sky",    "Ground",   "Bridge",    "RailTrack",  "GuardRail",
    "TrafficLight", "Static", "Dynamic", "Water",     "Terrain"};

const std::array<std::array<std::uint8_t, 3>, kNumTags> kCityscapesColors = {{
    {0, 0, 0},       {70, 70, 70},    {100, 40, 40},   {55, 90, 80},    {220, 20, 60},
    {153, 153, 153}, {157, 234, 50},  {128, 64, 128},  {244, 35, 232},  {107, 142, 35},
    {0, 0, 142},     {102, 102, 156}, {220, 220, 0},   {70, 130, 180},  {81, 0, 81},
    {150, 100, 100}, {230, 150, 140}, {180, 165, 180}, {250, 170, 30},  {110, 190, 160},
    {170, 120, 50},  {45, 60, 150},   {145, 170, 100}}};

std::vector<std::uint8_t> cityscapes_palette() {
  std::vector<std::uint8_t> p(256 * 3, 0);
  for (int t = 0; t < kNumTags; ++t)
    for (int c = 0; c < 3; ++c) p[3 * t + c] = kCityscapesColors[t][c];
  return p;
}

namespace {

struct FileCloser {
  void operator()(std::FILE* f) const noexcept { std::fclose(f); }
};
using File = std::unique_ptr<std::FILE, FileCloser>;

// Best p/q ~= x with q <= max_q (continued fractions); the frame period 1/fps as a PNG delay.
std::pair<std::uint32_t, std::uint32_t> rational(double x, std::uint32_t max_q) {
  std::uint64_t p0 = 0, q0 = 1, p1 = 1, q1 = 0;
  double r = x;
  for (int i = 0; i < 64; ++i) {
    const double a = std::floor(r);
    const std::uint64_t ai = static_cast<std::uint64_t>(a);
    const std::uint64_t p2 = ai * p1 + p0, q2 = ai * q1 + q0;
    if (q2 > max_q || p2 > 0xffff) break;
    p0 = p1, q0 = q1, p1 = p2, q1 = q2;
    if (r - a < 1e-12) break;
    r = 1.0 / (r - a);
  }
  return {static_cast<std::uint32_t>(p1), static_cast<std::uint32_t>(q1)};
}

// A stored frame waiting for its final delay (it grows while duplicates arrive).
struct PendingFrame {
  std::uint32_t x = 0, y = 0, w = 0, h = 0;
  std::vector<std::uint8_t> zdata;  // zlib stream of the filtered sub-rectangle
  std::int64_t repeats = 0;         // video frames this APNG frame stands for; 0 = none
};

struct Rect {
  std::size_t x = 0, y = 0, w = 0, h = 0;
};

// Bounding rectangle of the pixels where `a` and `b` differ; false when they are equal.
bool changed_rect(const std::uint8_t* a, const std::uint8_t* b, std::size_t width,
                  std::size_t height, Rect& r) {
  std::size_t y0 = 0, y1 = height;
  while (y0 < height && std::memcmp(a + y0 * width, b + y0 * width, width) == 0) ++y0;
  if (y0 == height) return false;
  while (std::memcmp(a + (y1 - 1) * width, b + (y1 - 1) * width, width) == 0) --y1;
  std::size_t x0 = width, x1 = 0;
  for (std::size_t y = y0; y < y1; ++y) {
    const std::uint8_t *ra = a + y * width, *rb = b + y * width;
    std::size_t lo = 0, hi = width;
    while (lo < x0 && ra[lo] == rb[lo]) ++lo;
    while (hi > x1 && hi > lo && ra[hi - 1] == rb[hi - 1]) --hi;
    x0 = std::min(x0, lo);
    x1 = std::max(x1, hi);
  }
  r = {x0, y0, x1 - x0, y1 - y0};
  return true;
}

}  // namespace

struct ApngWriter::Impl {
  std::string path;
  AtomicFile out;  // the temporary file, deleted unless close() renamed it into place
  int width = 0, height = 0;
  bool drop_duplicates = false;
  std::uint32_t delay_num = 1, delay_den = 30;  // one frame period
  File file;
  png::Compressor compressor;
  std::vector<std::uint8_t> canvas;    // last frame written, full size
  std::vector<std::uint8_t> filtered;  // scratch: filter byte + row, per row
  PendingFrame pending, next;
  std::uint32_t sequence = 0;  // fcTL/fdAT sequence number
  std::int64_t frames_in = 0, frames_out = 0;
  long actl_offset = 0;
  bool closed = false;

  ~Impl() { file.reset(); }  // closed before `out` deletes an unfinished file
  [[noreturn]] void fail(const std::string& what) const { throw ApngError(path + ": " + what); }
  void put(const void* data, std::size_t n);
  void chunk(const char* type, const std::uint8_t* head, std::size_t nh,
             const std::uint8_t* body = nullptr, std::size_t nb = 0);
  void write_header(const std::vector<std::uint8_t>& palette);
  void compress(const std::uint8_t* frame, std::uint32_t x, std::uint32_t y, std::uint32_t w,
                std::uint32_t h, PendingFrame& out);
  void emit(const PendingFrame& f, std::uint32_t delay_frames);
  void flush_pending();
};

void ApngWriter::Impl::put(const void* data, std::size_t n) {
  if (n && std::fwrite(data, 1, n, file.get()) != n)
    fail("write to " + out.path() + " failed: " + std::strerror(errno));
}

void ApngWriter::Impl::chunk(const char* type, const std::uint8_t* head, std::size_t nh,
                             const std::uint8_t* body, std::size_t nb) {
  const auto* t = reinterpret_cast<const std::uint8_t*>(type);
  std::uint8_t len[4], crc[4];
  png::put_u32(len, static_cast<std::uint32_t>(nh + nb));
  std::uint32_t c = png::chunk_crc(t, head, nh);
  if (nb) c = libdeflate_crc32(c, body, nb);
  png::put_u32(crc, c);
  put(len, 4);
  put(t, 4);
  put(head, nh);
  put(body, nb);
  put(crc, 4);
}

void ApngWriter::Impl::write_header(const std::vector<std::uint8_t>& palette) {
  put(png::kSignature, 8);
  std::uint8_t ihdr[13] = {0};
  png::put_u32(ihdr, static_cast<std::uint32_t>(width));
  png::put_u32(ihdr + 4, static_cast<std::uint32_t>(height));
  ihdr[8] = 8;  // bit depth
  ihdr[9] = 3;  // colour type: palette indices
  chunk("IHDR", ihdr, sizeof ihdr);
  chunk("PLTE", palette.data(), palette.size());
  actl_offset = std::ftell(file.get());
  const std::uint8_t actl[8] = {0};  // frame count patched by close(); 0 plays = loop
  chunk("acTL", actl, sizeof actl);
}

// Filters and deflates the w x h rectangle at (x, y) of `frame` into out.zdata.
void ApngWriter::Impl::compress(const std::uint8_t* frame, std::uint32_t x, std::uint32_t y,
                                std::uint32_t w, std::uint32_t h, PendingFrame& out) {
  filtered.resize(static_cast<std::size_t>(h) * (w + 1));
  const std::uint8_t* prev = nullptr;
  for (std::uint32_t r = 0; r < h; ++r) {
    const std::uint8_t* row = frame + static_cast<std::size_t>(y + r) * width + x;
    std::uint8_t* dst = filtered.data() + static_cast<std::size_t>(r) * (w + 1);
    dst[0] = png::choose_filter(row, prev, w);
    if (dst[0] == png::kNone)
      std::memcpy(dst + 1, row, w);
    else
      png::filter_row(dst[0], row, prev, w, 1, dst + 1);
    prev = row;
  }
  out.x = x, out.y = y, out.w = w, out.h = h;
  out.zdata.resize(libdeflate_zlib_compress_bound(compressor.get(), filtered.size()));
  const std::size_t n = libdeflate_zlib_compress(compressor.get(), filtered.data(),
                                                 filtered.size(), out.zdata.data(),
                                                 out.zdata.size());
  if (n == 0) fail("frame " + std::to_string(frames_in) + ": deflate failed");
  out.zdata.resize(n);
}

// Writes fcTL + IDAT (first frame) or fcTL + fdAT with a delay of `delay_frames` periods.
void ApngWriter::Impl::emit(const PendingFrame& f, std::uint32_t delay_frames) {
  std::uint8_t fctl[26] = {0};
  png::put_u32(fctl, sequence++);
  png::put_u32(fctl + 4, f.w);
  png::put_u32(fctl + 8, f.h);
  png::put_u32(fctl + 12, f.x);
  png::put_u32(fctl + 16, f.y);
  png::put_u16(fctl + 20, static_cast<std::uint16_t>(delay_frames * delay_num));
  png::put_u16(fctl + 22, static_cast<std::uint16_t>(delay_den));
  fctl[24] = 0;  // dispose_op NONE
  fctl[25] = 0;  // blend_op SOURCE
  chunk("fcTL", fctl, sizeof fctl);
  if (frames_out == 0) {
    chunk("IDAT", f.zdata.data(), f.zdata.size());
  } else {
    std::uint8_t seq[4];
    png::put_u32(seq, sequence++);
    chunk("fdAT", seq, 4, f.zdata.data(), f.zdata.size());
  }
  ++frames_out;
}

// Stores the pending frame. A delay too long for fcTL's 16-bit numerator is continued by
// 1x1 frames repeating a canvas pixel, so the timing stays exact.
void ApngWriter::Impl::flush_pending() {
  if (pending.repeats == 0) return;
  const std::int64_t max_frames = 0xffff / delay_num;
  std::int64_t left = pending.repeats;
  auto take = [&] { const std::int64_t k = std::min(left, max_frames); left -= k; return k; };
  emit(pending, static_cast<std::uint32_t>(take()));
  while (left > 0) {
    PendingFrame filler;
    compress(canvas.data(), pending.x, pending.y, 1, 1, filler);
    emit(filler, static_cast<std::uint32_t>(take()));
  }
  pending.repeats = 0;
}

ApngWriter::ApngWriter(std::string path, int width, int height,
                       const std::vector<std::uint8_t>& palette, double fps,
                       bool drop_duplicates, int level)
    : impl_(std::make_unique<Impl>()) {
  Impl& m = *impl_;
  m.path = std::move(path);
  m.width = width;
  m.height = height;
  m.drop_duplicates = drop_duplicates;
  if (width <= 0 || height <= 0)
    m.fail("width and height must be positive, got " + std::to_string(width) + "x" +
           std::to_string(height));
  if (palette.size() != 256 * 3)
    m.fail("palette must hold 256 RGB entries (768 bytes), got " + std::to_string(palette.size()) +
           " bytes");
  if (!(fps > 0) || !std::isfinite(fps)) m.fail("fps must be positive, got " + std::to_string(fps));
  std::tie(m.delay_num, m.delay_den) = rational(1.0 / fps, 0xffff);
  if (m.delay_num == 0) m.fail("fps " + std::to_string(fps) + " is too high for a PNG delay");
  m.compressor = png::make_compressor(level);
  if (!m.compressor) m.fail("libdeflate level must be 1..12, got " + std::to_string(level));
  m.out = AtomicFile(m.path);
  m.file.reset(std::fopen(m.out.path().c_str(), "wb"));
  if (!m.file) m.fail("cannot create " + m.out.path() + ": " + std::strerror(errno));
  m.canvas.assign(static_cast<std::size_t>(width) * height, 0);
  m.write_header(palette);
}

ApngWriter::~ApngWriter() = default;

void ApngWriter::write(const std::uint8_t* frame) {
  Impl& m = *impl_;
  if (m.closed) m.fail("write() after close()");
  const std::size_t w = static_cast<std::size_t>(m.width), h = static_cast<std::size_t>(m.height);
  Rect r{0, 0, w, h};
  if (m.frames_in > 0 && !changed_rect(m.canvas.data(), frame, w, h, r)) {
    if (m.drop_duplicates) {
      ++m.pending.repeats;
      ++m.frames_in;
      return;
    }
    r = {0, 0, 1, 1};  // APNG has no empty frame: repeat one unchanged pixel
  }
  m.compress(frame, static_cast<std::uint32_t>(r.x), static_cast<std::uint32_t>(r.y),
             static_cast<std::uint32_t>(r.w), static_cast<std::uint32_t>(r.h), m.next);
  m.flush_pending();  // before the canvas changes: a long delay may need its pixels
  std::swap(m.pending, m.next);
  m.pending.repeats = 1;
  std::memcpy(m.canvas.data() + r.y * w, frame + r.y * w, r.h * w);
  ++m.frames_in;
}

void ApngWriter::close() {
  Impl& m = *impl_;
  if (m.closed) return;
  if (m.frames_in == 0) m.fail("no frames were written (an APNG needs at least one)");
  m.flush_pending();
  m.chunk("IEND", nullptr, 0);
  // Patch acTL's frame count now that it is known (its CRC covers it).
  std::uint8_t actl[8] = {0};
  png::put_u32(actl, static_cast<std::uint32_t>(m.frames_out));
  if (std::fseek(m.file.get(), m.actl_offset, SEEK_SET) != 0)
    m.fail("cannot seek in " + m.out.path() + ": " + std::strerror(errno));
  m.chunk("acTL", actl, sizeof actl);
  if (std::fclose(m.file.release()) != 0)
    m.fail("cannot finish " + m.out.path() + ": " + std::strerror(errno));
  if (const int err = m.out.commit())
    m.fail("cannot rename " + m.out.path() + " into place: " + std::strerror(err));
  m.closed = true;
}

std::int64_t ApngWriter::frames_written() const { return impl_->frames_in; }
std::int64_t ApngWriter::frames_stored() const {
  return impl_->frames_out + (impl_->pending.repeats > 0 ? 1 : 0);
}
int ApngWriter::width() const { return impl_->width; }
int ApngWriter::height() const { return impl_->height; }
const std::string& ApngWriter::path() const { return impl_->path; }

}  // namespace bsp
