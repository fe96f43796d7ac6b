// ApngReader: the chunk index at open (png_chunks.cpp), then per frame inflate
// (libdeflate) -> unfilter -> dispose/blend onto a cached canvas.
#include <libdeflate.h>

#include <algorithm>
#include <array>
#include <cerrno>
#include <condition_variable>
#include <exception>
#include <thread>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <mutex>
#include <numeric>

#include "bsp/common/errors.hpp"
#include "bsp/media/apng.hpp"
#include "png.hpp"

namespace bsp {
namespace {

using png::FrameInfo;
using png::kBlendOver;
using png::kBlendSource;
using png::kDisposeNone;
using png::kDisposePrevious;

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

}  // namespace

// The file's bytes and its chunk index (png::FileIndex: header, palette, frame table,
// damage) plus the decoding state.
struct ApngReader::Impl : png::FileIndex {
  std::string path;
  std::vector<std::uint8_t> file;

  // Decoding state: `canvas` shows frame `current` (its dispose op not yet applied).
  std::mutex mutex;
  struct Buffers {
    std::vector<std::uint8_t> pixels, zbuf;
  };
  png::Decompressor inflater, ahead_inflater;  // one per thread
  std::vector<std::uint8_t> canvas, saved;
  Buffers own;                  // single-frame decoding
  std::array<Buffers, 4> ring;  // decoding ahead (DecodeAhead)
  std::int64_t current = -1;

  [[noreturn]] void fail(const std::string& what) const { throw ApngError(path + ": " + what); }
  [[noreturn]] void fail_frame(std::int64_t f, const std::string& what) const {
    fail("frame " + std::to_string(f) + ": " + what);
  }
  const std::uint8_t* decode(std::int64_t f, libdeflate_decompressor* inf, Buffers& b) const;
  void render(std::int64_t f, const std::uint8_t* px);
  void render(std::int64_t f) { render(f, decode(f, inflater.get(), own)); }
  class DecodeAhead;
  void read_sequence(const std::vector<std::int64_t>& indices,
                     const std::vector<std::size_t>& order, std::uint8_t* out);
  void dispose(std::int64_t f);
  void seek(std::int64_t f);
  bool independent(std::int64_t f) const;
};

// Inflates and unfilters frame f; returns its first pixel, rows w*channels + 1 bytes apart.
const std::uint8_t* ApngReader::Impl::decode(std::int64_t f, libdeflate_decompressor* inf,
                                             Buffers& b) const {
  const FrameInfo& fr = frames[static_cast<std::size_t>(f)];
  const std::size_t stride = fr.w * channels, expected = fr.h * (stride + 1);
  const std::uint8_t* src = file.data() + fr.data[0].first;
  std::size_t src_size = fr.data[0].second;
  if (fr.data.size() > 1) {  // a frame split over several chunks is one zlib stream
    b.zbuf.clear();
    for (auto [off, n] : fr.data) b.zbuf.insert(b.zbuf.end(), file.data() + off, file.data() + off + n);
    src = b.zbuf.data(), src_size = b.zbuf.size();
  }
  std::vector<std::uint8_t>& pixels = b.pixels;
  pixels.resize(expected);
  const libdeflate_result r =
      libdeflate_zlib_decompress(inf, src, src_size, pixels.data(), expected, nullptr);
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

// Draws frame f (decoded pixels `px`) over the canvas, which holds frame f-1 with its
// dispose op applied.
void ApngReader::Impl::render(std::int64_t f, const std::uint8_t* px) {
  const FrameInfo& fr = frames[static_cast<std::size_t>(f)];
  const std::size_t cstride = width * channels, fstride = fr.w * channels;
  std::uint8_t* at = canvas.data() + fr.y * cstride + fr.x * channels;
  if (fr.dispose == kDisposePrevious && f > 0) {
    saved.resize(fr.h * fstride);
    for (std::uint32_t y = 0; y < fr.h; ++y)
      std::memcpy(saved.data() + y * fstride, at + y * cstride, fstride);
  }
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

// Inflates and unfilters frames first..last on a helper thread, up to four ahead of the
// compositor: decoding needs only the file, so it overlaps with compositing and copying
// the previous frames out (the two halves of the work are about equal).
class ApngReader::Impl::DecodeAhead {
 public:
  DecodeAhead(Impl& m, std::int64_t first, std::int64_t last)
      : m_(m), first_(first), last_(last), thread_([this] { run(); }) {}
  ~DecodeAhead() {
    {
      std::lock_guard<std::mutex> lock(mu_);
      stop_ = true;
    }
    cv_.notify_all();
    thread_.join();
  }
  // Pixels of frame f (frames are taken in order); rethrows the error that stopped f.
  const std::uint8_t* get(std::int64_t f) {
    std::unique_lock<std::mutex> lock(mu_);
    cv_.wait(lock, [&] { return produced_ > f || error_; });
    if (produced_ <= f) std::rethrow_exception(error_);
    return ptr_[slot(f)];
  }
  // The frame from the last get() may be overwritten now.
  void release() {
    {
      std::lock_guard<std::mutex> lock(mu_);
      ++consumed_;
    }
    cv_.notify_all();
  }

 private:
  static constexpr std::int64_t kDepth = 4;
  std::size_t slot(std::int64_t f) const { return static_cast<std::size_t>(f % kDepth); }
  void run() {
    for (std::int64_t f = first_; f <= last_; ++f) {
      {
        std::unique_lock<std::mutex> lock(mu_);
        cv_.wait(lock, [&] { return f - (first_ + consumed_) < kDepth || stop_; });
        if (stop_) return;
      }
      try {
        const std::uint8_t* px = m_.decode(f, m_.ahead_inflater.get(), m_.ring[slot(f)]);
        std::lock_guard<std::mutex> lock(mu_);
        ptr_[slot(f)] = px;
        produced_ = f + 1;
      } catch (...) {
        std::lock_guard<std::mutex> lock(mu_);
        error_ = std::current_exception();
        cv_.notify_all();
        return;
      }
      cv_.notify_all();
    }
  }
  Impl& m_;  // the thread uses only decode(), ahead_inflater and ring
  const std::int64_t first_, last_;
  std::mutex mu_;
  std::condition_variable cv_;
  std::int64_t produced_ = 0, consumed_ = 0;  // produced_: frames below it are ready
  std::array<const std::uint8_t*, kDepth> ptr_{};
  bool stop_ = false;
  std::exception_ptr error_;
  std::thread thread_;  // last: starts after the members it uses exist
};

// read() for requests spanning several frames: one forward pass with decoding ahead.
void ApngReader::Impl::read_sequence(const std::vector<std::int64_t>& indices,
                                     const std::vector<std::size_t>& order, std::uint8_t* out) {
  const std::size_t frame_bytes = canvas.size();
  std::size_t next = 0;
  auto emit = [&] {
    for (; next < order.size() && indices[order[next]] == current; ++next)
      std::memcpy(out + order[next] * frame_bytes, canvas.data(), frame_bytes);
  };
  const std::int64_t t0 = indices[order.front()], t1 = indices[order.back()];
  std::int64_t from = current + 1;
  if (current >= 0 && t0 >= current) {
    emit();
  } else {
    for (from = t0; !independent(from);) --from;
    if (from == 0) std::fill(canvas.begin(), canvas.end(), std::uint8_t{0});
    current = -1;
  }
  if (from > t1) return;
  DecodeAhead ahead(*this, from, t1);
  for (std::int64_t f = from; f <= t1; ++f) {
    const std::uint8_t* px = ahead.get(f);
    if (current >= 0) dispose(current);
    current = -1;  // the canvas is between frames until render() returns
    render(f, px);
    current = f;
    ahead.release();
    emit();
  }
}

ApngReader::ApngReader(std::string path) : impl_(std::make_unique<Impl>()) {
  Impl& m = *impl_;
  m.path = std::move(path);
  m.file = read_file(m.path);
  static_cast<png::FileIndex&>(m) = png::index_png(m.file, m.path);
  m.inflater = png::make_decompressor();
  m.ahead_inflater = png::make_decompressor();
  if (!m.inflater || !m.ahead_inflater) m.fail("cannot allocate a libdeflate decompressor");
  // The canvas is allocated by the first read(), so that a caller can check width() and
  // height() against what it expects before any frame-sized memory is taken.
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

std::string ApngReader::damage() const {
  if (impl_->bad_frame < 0) return {};
  return "frame " + std::to_string(impl_->bad_frame) + ": " + impl_->bad_reason;
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
  std::lock_guard<std::mutex> lock(m.mutex);
  if (m.canvas.empty()) m.canvas.assign(std::size_t{m.width} * m.height * m.channels, 0);
  const std::size_t frame_bytes = m.canvas.size();
  // Decoding ahead pays for its thread once a request spans a few frames.
  if (order.size() > 1 && indices[order.back()] - indices[order.front()] >= 4)
    return m.read_sequence(indices, order, out);
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
