// ApngReader: chunk walk at open (CRCs, sequence numbers, frame table), then per frame
// inflate (libdeflate) -> unfilter -> dispose/blend onto a cached canvas.
#include <libdeflate.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <mutex>
#include <numeric>

#include "bsp/apng.hpp"
#include "bsp/errors.hpp"
#include "bsp/png_common.hpp"

namespace bsp {
namespace {

enum : std::uint8_t { kDisposeNone = 0, kDisposeBackground = 1, kDisposePrevious = 2 };
enum : std::uint8_t { kBlendSource = 0, kBlendOver = 1 };

struct FrameInfo {
  std::uint32_t x = 0, y = 0, w = 0, h = 0;
  std::uint16_t delay_num = 0, delay_den = 100;
  std::uint8_t dispose = kDisposeNone, blend = kBlendSource;
  std::vector<std::pair<std::size_t, std::size_t>> data;  // zlib pieces: (offset, size)
};

std::vector<std::uint8_t> read_file(const std::string& path) {
  std::unique_ptr<std::FILE, int (*)(std::FILE*)> f(std::fopen(path.c_str(), "rb"), &std::fclose);
  if (!f) throw ApngError(path + ": cannot open: " + std::strerror(errno));
  std::vector<std::uint8_t> buf;
  std::uint8_t chunk[1 << 16];
  std::size_t n;
  while ((n = std::fread(chunk, 1, sizeof chunk, f.get())) > 0) buf.insert(buf.end(), chunk, chunk + n);
  if (std::ferror(f.get())) throw ApngError(path + ": read error: " + std::strerror(errno));
  return buf;
}

int channels_of(int colour_type) {
  switch (colour_type) {
    case 0: return 1;
    case 2: return 3;
    case 3: return 1;
    case 4: return 2;
    case 6: return 4;
    default: return 0;
  }
}

}  // namespace

struct ApngReader::Impl {
  std::string path;
  std::vector<std::uint8_t> file;
  std::uint32_t width = 0, height = 0;
  int colour_type = 0;
  std::size_t channels = 1;
  std::vector<std::uint8_t> palette;
  std::uint8_t palette_alpha[256];
  std::uint8_t key[4] = {0};  // tRNS colour key (8-bit samples) for grey/RGB
  bool has_key = false, has_trns = false;
  std::vector<FrameInfo> frames;
  std::int64_t declared = -1;  // acTL num_frames; -1 = plain PNG
  std::int64_t bad_frame = -1;  // first frame that cannot be decoded, -1 = none
  std::string bad_reason;

  // Decoding state: `canvas` shows frame `current` (its dispose op not yet applied).
  std::mutex mutex;
  png::Decompressor inflater;
  std::vector<std::uint8_t> canvas, saved, pixels, zbuf;
  std::int64_t current = -1;

  [[noreturn]] void fail(const std::string& what) const { throw ApngError(path + ": " + what); }
  [[noreturn]] void fail_frame(std::int64_t f, const std::string& what) const {
    fail("frame " + std::to_string(f) + ": " + what);
  }
  void parse();
  bool handle_chunk(const std::uint8_t* type, const std::uint8_t* d, std::uint32_t len,
                    std::size_t at, std::uint32_t& seq, bool& seen_idat);
  void read_ihdr(const std::uint8_t* d, std::uint32_t len);
  void read_trns(const std::uint8_t* d, std::uint32_t len);
  void read_fctl(const std::uint8_t* d, std::uint32_t len, std::uint32_t& seq);
  void mark_bad(std::int64_t frame, const std::string& why);
  std::int64_t frame_of_next_data() const { return std::max<std::int64_t>(0, static_cast<std::int64_t>(frames.size()) - 1); }

  const std::uint8_t* decode(std::int64_t f);
  void render(std::int64_t f);
  void dispose(std::int64_t f);
  void seek(std::int64_t f);
  bool independent(std::int64_t f) const;
};

void ApngReader::Impl::mark_bad(std::int64_t frame, const std::string& why) {
  if (bad_frame < 0 || frame < bad_frame) {
    bad_frame = frame;
    bad_reason = why;
  }
}

void ApngReader::Impl::read_ihdr(const std::uint8_t* d, std::uint32_t len) {
  if (len != 13) fail("IHDR has " + std::to_string(len) + " bytes, expected 13");
  width = png::get_u32(d);
  height = png::get_u32(d + 4);
  const int depth = d[8];
  colour_type = d[9];
  if (width == 0 || height == 0 || width > (1u << 24) || height > (1u << 24))
    fail("invalid image size " + std::to_string(width) + "x" + std::to_string(height));
  if (channels_of(colour_type) == 0)
    fail("unsupported colour type " + std::to_string(colour_type));
  if (depth != 8)
    fail("unsupported bit depth " + std::to_string(depth) + " (only 8-bit PNGs are supported)");
  if (d[10] != 0 || d[11] != 0) fail("unknown compression or filter method in IHDR");
  if (d[12] != 0) fail("interlaced (Adam7) PNGs are not supported");
  channels = static_cast<std::size_t>(channels_of(colour_type));
}

void ApngReader::Impl::read_trns(const std::uint8_t* d, std::uint32_t len) {
  if (colour_type == 3) {
    std::memcpy(palette_alpha, d, std::min<std::size_t>(len, 256));
    has_trns = true;
  } else if (colour_type == 0 || colour_type == 2) {
    if (len != 2 * channels) fail("tRNS has " + std::to_string(len) + " bytes");
    // An 8-bit image's samples fit the low byte; a key with a high byte never matches.
    has_key = true;
    for (std::size_t c = 0; c < channels; ++c) {
      key[c] = d[2 * c + 1];
      has_key = has_key && d[2 * c] == 0;
    }
  }
}

void ApngReader::Impl::read_fctl(const std::uint8_t* d, std::uint32_t len, std::uint32_t& seq) {
  const auto f = static_cast<std::int64_t>(frames.size());
  if (len != 26) return mark_bad(f, "fcTL has " + std::to_string(len) + " bytes, expected 26");
  if (png::get_u32(d) != seq)
    return mark_bad(f, "fcTL sequence number " + std::to_string(png::get_u32(d)) + ", expected " +
                           std::to_string(seq));
  ++seq;
  FrameInfo fr;
  fr.w = png::get_u32(d + 4), fr.h = png::get_u32(d + 8);
  fr.x = png::get_u32(d + 12), fr.y = png::get_u32(d + 16);
  fr.delay_num = png::get_u16(d + 20), fr.delay_den = png::get_u16(d + 22);
  fr.dispose = d[24], fr.blend = d[25];
  if (fr.delay_den == 0) fr.delay_den = 100;  // APNG spec: 0 means 1/100 s
  frames.push_back(fr);
  if (fr.w == 0 || fr.h == 0 || fr.x >= width || fr.y >= height || fr.w > width - fr.x ||
      fr.h > height - fr.y)
    return mark_bad(f, "fcTL region " + std::to_string(fr.w) + "x" + std::to_string(fr.h) + "+" +
                           std::to_string(fr.x) + "+" + std::to_string(fr.y) +
                           " is outside the " + std::to_string(width) + "x" +
                           std::to_string(height) + " canvas");
  if (f == 0 && (fr.x || fr.y || fr.w != width || fr.h != height))
    return mark_bad(f, "the first fcTL must cover the whole canvas");
  if (fr.dispose > kDisposePrevious) return mark_bad(f, "unknown dispose_op " + std::to_string(fr.dispose));
  if (fr.blend > kBlendOver) return mark_bad(f, "unknown blend_op " + std::to_string(fr.blend));
}

// Returns true at IEND. Frame-level problems are recorded with mark_bad.
bool ApngReader::Impl::handle_chunk(const std::uint8_t* type, const std::uint8_t* d,
                                    std::uint32_t len, std::size_t at, std::uint32_t& seq,
                                    bool& seen_idat) {
  auto is = [&](const char* t) { return std::memcmp(type, t, 4) == 0; };
  if (is("IHDR")) {
    read_ihdr(d, len);
  } else if (is("PLTE")) {
    if (len % 3 || len == 0 || len > 768) fail("PLTE has " + std::to_string(len) + " bytes");
    palette.assign(d, d + len);
  } else if (is("tRNS")) {
    read_trns(d, len);
  } else if (is("acTL")) {
    if (len != 8) fail("acTL has " + std::to_string(len) + " bytes, expected 8");
    declared = png::get_u32(d);
    if (declared == 0) fail("acTL declares 0 frames");
  } else if (is("fcTL")) {
    read_fctl(d, len, seq);
  } else if (is("IDAT")) {
    seen_idat = true;
    if (declared < 0 || frames.size() == 1) {
      if (frames.empty()) frames.emplace_back();  // plain PNG: the image is frame 0
      frames.back().data.emplace_back(at, len);
    } else if (!frames.empty()) {
      mark_bad(frame_of_next_data(), "IDAT after the first animation frame");
    }  // else: a default image that is not part of the animation (skipped)
  } else if (is("fdAT")) {
    const std::int64_t f = frame_of_next_data();
    if (len < 4 || frames.empty()) return mark_bad(f, "fdAT without a frame"), false;
    if (png::get_u32(d) != seq)
      return mark_bad(f, "fdAT sequence number " + std::to_string(png::get_u32(d)) +
                             ", expected " + std::to_string(seq)), false;
    ++seq;
    frames.back().data.emplace_back(at + 4, len - 4);
  } else if (is("IEND")) {
    return true;
  }
  return false;
}

namespace {
std::string chunk_name(const std::uint8_t* t) {
  std::string s;
  for (int i = 0; i < 4; ++i)
    s += (t[i] >= 32 && t[i] < 127) ? static_cast<char>(t[i]) : '?';
  return s;
}
}  // namespace

// Walks the chunks once. Damage before the first frame's data makes the file unusable and
// throws; later damage is recorded against the frame it belongs to (see mark_bad).
void ApngReader::Impl::parse() {
  const std::size_t size = file.size();
  if (size < 8 || std::memcmp(file.data(), png::kSignature, 8) != 0)
    fail(size == 0 ? "empty file" : "not a PNG file (bad signature)");
  std::uint32_t seq = 0;
  bool seen_idat = false, ended = false;
  std::size_t pos = 8;
  while (!ended && bad_frame < 0) {
    const bool headers_done = !frames.empty() || seen_idat;
    auto damage = [&](const std::string& why, bool starts_frame) {
      if (!headers_done) fail(why);
      mark_bad(starts_frame ? static_cast<std::int64_t>(frames.size()) : frame_of_next_data(), why);
    };
    if (pos + 8 > size) {
      damage("truncated file: it ends at byte " + std::to_string(size) + " before IEND", false);
      break;
    }
    const std::uint8_t* p = file.data() + pos;
    const std::uint32_t len = png::get_u32(p);
    const std::string name = chunk_name(p + 4);
    if (len > 0x7fffffffu || pos + 12 + len > size) {
      damage("truncated file: chunk " + name + " at byte " + std::to_string(pos) + " needs " +
                 std::to_string(12ull + len) + " bytes, the file has " + std::to_string(size - pos) +
                 " left",
             name == "fcTL");
      break;
    }
    if (png::get_u32(p + 8 + len) != png::chunk_crc(p + 4, p + 8, len)) {
      damage("bad CRC in chunk " + name + " at byte " + std::to_string(pos) + " (file corrupt)",
             name == "fcTL");
      break;
    }
    if (pos == 8 && name != "IHDR") fail("first chunk is " + name + ", expected IHDR");
    ended = handle_chunk(p + 4, p + 8, len, pos + 8, seq, seen_idat);
    pos += 12 + std::size_t{len};
  }
  if (!seen_idat && frames.empty()) fail("no image data (IDAT) before the damage or the end");
  if (colour_type == 3 && palette.empty()) fail("palette image without a PLTE chunk");
  if (declared < 0) {  // plain PNG: one full frame
    frames.resize(1);
    frames[0].w = width, frames[0].h = height;
    frames[0].delay_num = 0;
    declared = 1;
  }
  if (bad_frame < 0 && static_cast<std::int64_t>(frames.size()) != declared)
    fail("acTL declares " + std::to_string(declared) + " frames but the file holds " +
         std::to_string(frames.size()));
  for (std::size_t f = 0; f < frames.size(); ++f)
    if (frames[f].data.empty() && (bad_frame < 0 || static_cast<std::int64_t>(f) < bad_frame))
      mark_bad(static_cast<std::int64_t>(f), "no image data after its fcTL");
}

// Inflates and unfilters frame f; returns its first pixel, rows w*channels + 1 bytes apart.
const std::uint8_t* ApngReader::Impl::decode(std::int64_t f) {
  const FrameInfo& fr = frames[static_cast<std::size_t>(f)];
  const std::size_t stride = fr.w * channels, expected = fr.h * (stride + 1);
  const std::uint8_t* src = file.data() + fr.data[0].first;
  std::size_t src_size = fr.data[0].second;
  if (fr.data.size() > 1) {  // a frame split over several chunks is one zlib stream
    zbuf.clear();
    for (auto [off, n] : fr.data) zbuf.insert(zbuf.end(), file.data() + off, file.data() + off + n);
    src = zbuf.data(), src_size = zbuf.size();
  }
  pixels.resize(expected);
  const libdeflate_result r =
      libdeflate_zlib_decompress(inflater.get(), src, src_size, pixels.data(), expected, nullptr);
  if (r == LIBDEFLATE_SHORT_OUTPUT) fail_frame(f, "image data too short for its fcTL size");
  if (r == LIBDEFLATE_INSUFFICIENT_SPACE) fail_frame(f, "image data too long for its fcTL size");
  if (r != LIBDEFLATE_SUCCESS) fail_frame(f, "corrupt zlib image data");
  // Unfilter in place: row y's pixels stay at pixels + y * (stride + 1) + 1.
  const std::uint8_t* prev = nullptr;
  for (std::uint32_t y = 0; y < fr.h; ++y) {
    std::uint8_t* row = pixels.data() + y * (stride + 1);
    if (!png::unfilter_row(row[0], row + 1, prev, stride, channels))
      fail_frame(f, "row " + std::to_string(y) + " has unknown filter type " + std::to_string(row[0]));
    prev = row + 1;
  }
  return pixels.data() + 1;
}

// Draws frame f over the canvas, which holds frame f-1 with its dispose op applied.
void ApngReader::Impl::render(std::int64_t f) {
  const FrameInfo& fr = frames[static_cast<std::size_t>(f)];
  const std::size_t cstride = width * channels, fstride = fr.w * channels;
  std::uint8_t* at = canvas.data() + fr.y * cstride + fr.x * channels;
  if (fr.dispose == kDisposePrevious && f > 0) {
    saved.resize(fr.h * fstride);
    for (std::uint32_t y = 0; y < fr.h; ++y)
      std::memcpy(saved.data() + y * fstride, at + y * cstride, fstride);
  }
  const std::uint8_t* px = decode(f);
  // Frame 0 is copied whatever its blend op, like Pillow and FFmpeg.
  const bool over = fr.blend == kBlendOver && f > 0;
  for (std::uint32_t y = 0; y < fr.h; ++y) {
    std::uint8_t* dst = at + y * cstride;
    const std::uint8_t* src = px + y * (fstride + 1);
    if (over && (colour_type == 4 || colour_type == 6))
      png::blend_over_alpha(dst, src, fr.w, channels);
    else if (over && colour_type == 3 && has_trns)
      png::blend_over_palette(dst, src, fr.w, palette_alpha);
    else if (over && has_key)
      png::blend_over_key(dst, src, fr.w, channels, key);
    else
      std::memcpy(dst, src, fstride);
  }
}

// Applies frame f's dispose op to its region (PREVIOUS on frame 0 acts as BACKGROUND).
void ApngReader::Impl::dispose(std::int64_t f) {
  const FrameInfo& fr = frames[static_cast<std::size_t>(f)];
  if (fr.dispose == kDisposeNone) return;
  const std::size_t cstride = width * channels, fstride = fr.w * channels;
  std::uint8_t* at = canvas.data() + fr.y * cstride + fr.x * channels;
  const bool restore = fr.dispose == kDisposePrevious && f > 0;
  for (std::uint32_t y = 0; y < fr.h; ++y) {
    if (restore)
      std::memcpy(at + y * cstride, saved.data() + y * fstride, fstride);
    else
      std::memset(at + y * cstride, 0, fstride);
  }
}

// True when drawing frame f needs no earlier frame: it replaces the whole canvas and does
// not ask to restore what was there before. Seeking back restarts from such a frame.
bool ApngReader::Impl::independent(std::int64_t f) const {
  if (f == 0) return true;
  const FrameInfo& fr = frames[static_cast<std::size_t>(f)];
  const bool transparent = colour_type == 4 || colour_type == 6 || has_trns || has_key;
  return fr.x == 0 && fr.y == 0 && fr.w == width && fr.h == height &&
         (fr.blend == kBlendSource || !transparent) && fr.dispose != kDisposePrevious;
}

void ApngReader::Impl::seek(std::int64_t t) {
  if (current < 0 || t < current) {
    std::int64_t start = t;
    while (!independent(start)) --start;
    if (start == 0) std::fill(canvas.begin(), canvas.end(), std::uint8_t{0});
    current = -1;
    render(start);
    current = start;
  }
  while (current < t) {
    const std::int64_t next = current + 1;
    dispose(current);
    current = -1;  // the canvas is between frames until render() returns
    render(next);
    current = next;
  }
}

ApngReader::ApngReader(std::string path) : impl_(std::make_unique<Impl>()) {
  Impl& m = *impl_;
  m.path = std::move(path);
  std::memset(m.palette_alpha, 255, sizeof m.palette_alpha);
  m.file = read_file(m.path);
  m.parse();
  m.inflater = png::make_decompressor();
  if (!m.inflater) m.fail("cannot allocate a libdeflate decompressor");
  m.canvas.assign(static_cast<std::size_t>(m.width) * m.height * m.channels, 0);
}

ApngReader::~ApngReader() = default;

std::int64_t ApngReader::frame_count() const { return impl_->declared; }
int ApngReader::width() const { return static_cast<int>(impl_->width); }
int ApngReader::height() const { return static_cast<int>(impl_->height); }
int ApngReader::channels() const { return static_cast<int>(impl_->channels); }
int ApngReader::colour_type() const { return impl_->colour_type; }
bool ApngReader::indexed() const { return impl_->colour_type == 3; }
std::vector<std::uint8_t> ApngReader::palette() const { return impl_->palette; }

std::vector<double> ApngReader::delays() const {
  std::vector<double> d;
  for (const FrameInfo& f : impl_->frames) d.push_back(double(f.delay_num) / f.delay_den);
  d.resize(static_cast<std::size_t>(impl_->declared), 0.0);  // frames lost to damage
  return d;
}

std::vector<std::uint8_t> ApngReader::dispose_ops() const {
  std::vector<std::uint8_t> d;
  for (const FrameInfo& f : impl_->frames) d.push_back(f.dispose);
  return d;
}

std::vector<std::uint8_t> ApngReader::blend_ops() const {
  std::vector<std::uint8_t> d;
  for (const FrameInfo& f : impl_->frames) d.push_back(f.blend);
  return d;
}

void ApngReader::read(const std::vector<std::int64_t>& indices, std::uint8_t* out) {
  Impl& m = *impl_;
  const std::int64_t n = m.declared;
  for (std::int64_t i : indices) {
    if (i < 0 || i >= n)
      m.fail("frame " + std::to_string(i) + " requested but file has " + std::to_string(n) +
             " frames");
    if (m.bad_frame >= 0 && i >= m.bad_frame)
      m.fail(i == m.bad_frame ? "frame " + std::to_string(i) + ": " + m.bad_reason
                              : "frame " + std::to_string(i) + " cannot be decoded: frame " +
                                    std::to_string(m.bad_frame) + ": " + m.bad_reason);
  }
  // Visit frames in display order so one forward pass serves the whole request.
  std::vector<std::size_t> order(indices.size());
  std::iota(order.begin(), order.end(), std::size_t{0});
  std::stable_sort(order.begin(), order.end(),
                   [&](std::size_t a, std::size_t b) { return indices[a] < indices[b]; });
  const std::size_t frame_bytes = m.canvas.size();
  std::lock_guard<std::mutex> lock(m.mutex);
  for (std::size_t p : order) {
    m.seek(indices[p]);
    std::memcpy(out + p * frame_bytes, m.canvas.data(), frame_bytes);
  }
}

std::vector<std::int64_t> ApngReader::video_to_apng_frames(std::int64_t n_video_frames,
                                                           double fps) const {
  if (!(fps > 0) || !std::isfinite(fps)) impl_->fail("fps must be positive");
  const auto& frames = impl_->frames;
  std::vector<long double> start(frames.size() + 1, 0.0L);  // start[j]: when frame j appears
  for (std::size_t j = 0; j < frames.size(); ++j)
    start[j + 1] = start[j] + static_cast<long double>(frames[j].delay_num) / frames[j].delay_den;
  // Video frame times k / fps and sums of delays agree up to rounding; a tolerance of a
  // millionth of a frame keeps k exactly on a boundary on the new frame's side.
  const long double eps = 1e-6L / fps;
  std::vector<std::int64_t> out(static_cast<std::size_t>(std::max<std::int64_t>(n_video_frames, 0)), -1);
  std::size_t j = 0;
  for (std::size_t k = 0; k < out.size(); ++k) {
    const long double t = static_cast<long double>(k) / fps;
    while (j + 1 < frames.size() && start[j + 1] <= t + eps) ++j;
    if (t + eps < start.back()) out[k] = static_cast<std::int64_t>(j);
  }
  return out;
}

}  // namespace bsp
