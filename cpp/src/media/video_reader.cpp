// VideoReader: a packet scan at open gives the exact display-order timestamp of every
// frame; reads then decode forward from the nearest keyframe and identify each decoded
// frame by its timestamp, converting only the frames asked for.
#include <algorithm>
#include <condition_variable>
#include <deque>
#include <exception>
#include <mutex>
#include <numeric>
#include <optional>
#include <thread>

#include "bsp/common/errors.hpp"
#include "bsp/media/video.hpp"
#include "ffmpeg.hpp"

extern "C" {
#include <libavutil/pixdesc.h>
}

namespace bsp {

struct VideoReader::Impl {
  std::string path;
  av::InputFormat fmt;
  av::CodecContext dec;
  av::Packet pkt;
  av::Frame frame;
  av::Sws sws;
  int stream = -1;
  std::vector<std::int64_t> pts;   // display order: pts[k] is frame k's timestamp
  std::vector<std::int64_t> keys;  // display indices of keyframes, ascending
  bool timestamps = true;  // frames identified by pts; false when pts are missing or repeated
  bool use_keys = true;    // seek to keyframes; false once a seek misbehaved
  std::int64_t count = 0;
  std::int64_t bad_frame = -1;  // first frame lost to a damaged or truncated file
  std::string bad_reason;
  // Decoder position: `last` is the display index of the frame in `frame` (-1: none yet).
  std::int64_t last = -1;
  bool draining = false;
  bool lost = false;  // an error interrupted decoding: reposition before the next read
  std::mutex mutex;
  std::vector<std::uint8_t> scratch;

  [[noreturn]] void fail(const std::string& what) const { throw VideoDecodeError(path + ": " + what); }
  std::string at(std::int64_t k) const { return "frame " + std::to_string(k) + ": "; }
  void open(int threads);
  void scan();
  void rewind_to(std::int64_t key_index);
  bool next_frame(std::int64_t target);
  std::int64_t index_of(std::int64_t ts) const;
  void goto_frame(std::int64_t k);
  void convert(const AVFrame& f, std::uint8_t* out, const Crop& c);
  class Converter;
};

void VideoReader::Impl::open(int threads) {
  av::quiet_logs();
  AVFormatContext* raw = nullptr;
  // Untrusted files: the MP4/MOV demuxer only (no probing, so a playlist or a concat script
  // named .mp4 is not followed) and the "file" protocol only (nothing else is opened).
  AVDictionary* opts = nullptr;
  av_dict_set(&opts, "protocol_whitelist", "file", 0);
  const int opened = avformat_open_input(&raw, path.c_str(), av_find_input_format("mp4"), &opts);
  av_dict_free(&opts);
  BSP_AV_CHECK(VideoDecodeError, opened, path, "cannot open as an MP4/MOV file");
  fmt.reset(raw);
  BSP_AV_CHECK(VideoDecodeError, avformat_find_stream_info(fmt.get(), nullptr), path,
               "cannot read the stream parameters");
  const AVCodec* codec = nullptr;
  stream = av_find_best_stream(fmt.get(), AVMEDIA_TYPE_VIDEO, -1, -1, &codec, 0);
  BSP_AV_CHECK(VideoDecodeError, stream, path, "no decodable video stream");
  for (unsigned i = 0; i < fmt->nb_streams; ++i)
    if (static_cast<int>(i) != stream) fmt->streams[i]->discard = AVDISCARD_ALL;
  dec.reset(avcodec_alloc_context3(codec));
  if (!dec) fail("cannot allocate the decoder");
  BSP_AV_CHECK(VideoDecodeError,
               avcodec_parameters_to_context(dec.get(), fmt->streams[stream]->codecpar), path,
               "decoder parameters");
  // FFmpeg's own automatic choice is cores + 1 frame threads; one more decoding frame in
  // flight keeps the cores busy while the caller's thread waits on the RGB converter
  // (measured on 2 cores: 4 threads beat 3 by ~10 %).
  if (threads == 0)
    threads = static_cast<int>(std::min(16u, std::max(1u, std::thread::hardware_concurrency()) + 2));
  dec->thread_count = threads;
  dec->thread_type = FF_THREAD_FRAME | FF_THREAD_SLICE;
  // A damaged bitstream is an error naming the frame, not a silently concealed picture.
  dec->err_recognition |= AV_EF_EXPLODE;
  BSP_AV_CHECK(VideoDecodeError, avcodec_open2(dec.get(), codec, nullptr), path,
               "cannot open the decoder");
  // A damaged stream header can leave the size unknown even after the probe decoded
  // frames (found by tests/fuzz/fuzz_video): refuse it instead of reporting a 0x0 video.
  if (dec->width <= 0 || dec->height <= 0)
    fail("the video stream has no valid picture size (" + std::to_string(dec->width) + "x" +
         std::to_string(dec->height) + ")");
  pkt = av::alloc_packet<VideoDecodeError>(path);
  frame = av::alloc_frame<VideoDecodeError>(path);
}

// Reads every packet once (no decoding) to learn the shown frames' timestamps. Packets
// an edit list discards produce no frame and are not counted.
void VideoReader::Impl::scan() {
  std::vector<std::int64_t> key_pts;
  int ret;
  while ((ret = av_read_frame(fmt.get(), pkt.get())) >= 0) {
    if (pkt->stream_index == stream && !(pkt->flags & AV_PKT_FLAG_DISCARD)) {
      if (pkt->flags & AV_PKT_FLAG_CORRUPT) {
        bad_reason = "truncated or damaged data in packet " + std::to_string(pts.size());
        av_packet_unref(pkt.get());
        break;
      }
      const std::int64_t ts = pkt->pts != AV_NOPTS_VALUE ? pkt->pts : pkt->dts;
      timestamps = timestamps && ts != AV_NOPTS_VALUE;
      pts.push_back(ts);
      if (pkt->flags & AV_PKT_FLAG_KEY) key_pts.push_back(ts);
    }
    av_packet_unref(pkt.get());
  }
  if (ret < 0 && ret != AVERROR_EOF)
    bad_reason = "cannot read packet " + std::to_string(pts.size()) + ": " + av::error_text(ret);
  std::sort(pts.begin(), pts.end());
  timestamps = timestamps && std::adjacent_find(pts.begin(), pts.end()) == pts.end();
  for (std::int64_t ts : key_pts)
    keys.push_back(std::lower_bound(pts.begin(), pts.end(), ts) - pts.begin());
  std::sort(keys.begin(), keys.end());
  if (keys.empty() || keys.front() != 0) keys.insert(keys.begin(), 0);
  count = static_cast<std::int64_t>(pts.size());
  if (!bad_reason.empty()) {
    // Frames reorder: the damaged packet may be shown a few frames before its decode slot.
    const int delay = std::max(dec->has_b_frames, fmt->streams[stream]->codecpar->video_delay);
    bad_frame = std::max<std::int64_t>(0, count - 1 - delay);
  }
  if (count == 0) fail(bad_reason.empty() ? "the video stream has no frames" : bad_reason);
  rewind_to(0);
}

// Restarts decoding at keyframe display index `key` (0 = the start of the stream).
void VideoReader::Impl::rewind_to(std::int64_t key) {
  const int ret = timestamps
                      ? av_seek_frame(fmt.get(), stream, pts[static_cast<std::size_t>(key)],
                                      AVSEEK_FLAG_BACKWARD)
                      : av_seek_frame(fmt.get(), stream, 0, AVSEEK_FLAG_BYTE);
  BSP_AV_CHECK(VideoDecodeError, ret, path, at(key) + "cannot seek");
  avcodec_flush_buffers(dec.get());
  last = -1;
  draining = false;
}

std::int64_t VideoReader::Impl::index_of(std::int64_t ts) const {
  const auto it = std::lower_bound(pts.begin(), pts.end(), ts);
  return (it != pts.end() && *it == ts) ? it - pts.begin() : -1;
}

// Decodes the next frame in display order into `frame` and sets `last` to its index.
// Returns false at the end of the stream. `target` only labels errors.
bool VideoReader::Impl::next_frame(std::int64_t target) {
  for (;;) {
    int ret = avcodec_receive_frame(dec.get(), frame.get());
    if (ret >= 0) {
      if (!timestamps) {
        ++last;
        return true;
      }
      const std::int64_t k = index_of(frame->best_effort_timestamp);
      if (k < 0) fail(at(target) + "decoded a frame whose timestamp no packet had");
      last = k;
      return true;
    }
    if (ret == AVERROR_EOF) return false;
    if (ret != AVERROR(EAGAIN) || draining)
      fail(at(target) + "decoding failed: " + av::error_text(ret));
    ret = av_read_frame(fmt.get(), pkt.get());
    if (ret == AVERROR_EOF) {
      draining = true;
      BSP_AV_CHECK(VideoDecodeError, avcodec_send_packet(dec.get(), nullptr), path,
                   at(target) + "flush the decoder");
      continue;
    }
    BSP_AV_CHECK(VideoDecodeError, ret, path, at(target) + "cannot read a packet");
    if (pkt->stream_index == stream) ret = avcodec_send_packet(dec.get(), pkt.get());
    av_packet_unref(pkt.get());
    if (ret < 0) fail(at(target) + "decoding failed: " + av::error_text(ret));
  }
}

// Leaves frame k in `frame`, decoding forward and seeking only when that is cheaper.
void VideoReader::Impl::goto_frame(std::int64_t k) {
  if (last == k && !lost) return;
  std::int64_t key = *(std::upper_bound(keys.begin(), keys.end(), k) - 1);
  if (!use_keys || !timestamps) key = 0;
  if (lost || k < last || key > last + 1) rewind_to(key);
  lost = false;
  for (int attempt = 0;; ++attempt) {
    while (last < k)
      if (!next_frame(k))
        fail("frame " + std::to_string(k) + " requested but the stream ended after " +
             std::to_string(last + 1) + " frames");
    if (last == k) return;
    // The seek landed past the keyframe (timestamps disagree with the index): start over
    // from the beginning, which always works, and never seek again.
    if (attempt > 0 || key == 0) fail(at(k) + "frame not found while decoding");
    use_keys = false;
    rewind_to(0);
    key = 0;
  }
}

namespace {

int sws_colorspace(AVColorSpace cs) {
  switch (cs) {
    case AVCOL_SPC_BT709: return SWS_CS_ITU709;
    case AVCOL_SPC_FCC: return SWS_CS_FCC;
    case AVCOL_SPC_SMPTE240M: return SWS_CS_SMPTE240M;
    case AVCOL_SPC_BT2020_NCL:
    case AVCOL_SPC_BT2020_CL: return SWS_CS_BT2020;
    default: return SWS_CS_DEFAULT;  // BT.601, also what "unspecified" means to swscale
  }
}

// Pointers to pixel (x, y) of each plane, as av_frame_apply_cropping computes them; x and
// y must be multiples of the chroma subsampling.
void plane_offsets(const AVFrame& f, const AVPixFmtDescriptor& d, int x, int y,
                   const std::uint8_t* src[4]) {
  for (int p = 0; p < 4; ++p) {
    src[p] = f.data[p];
    if (!f.data[p] || ((d.flags & AV_PIX_FMT_FLAG_PAL) && p == 1)) continue;
    const bool chroma = p == 1 || p == 2;
    int step = 0;
    for (int c = 0; c < d.nb_components && !step; ++c)
      if (d.comp[c].plane == p) step = d.comp[c].step;
    src[p] += (y >> (chroma ? d.log2_chroma_h : 0)) * static_cast<std::ptrdiff_t>(f.linesize[p]) +
              (x >> (chroma ? d.log2_chroma_w : 0)) * step;
  }
}

}  // namespace

// Converts the crop of `frame` to RGB24 at `out` (rows c.width * 3 bytes). Only the
// cropped pixels are converted, widened to 8-pixel column blocks and whole chroma rows;
// the extra pixels are dropped after conversion.
void VideoReader::Impl::convert(const AVFrame& f, std::uint8_t* out, const Crop& c) {
  const auto pix = static_cast<AVPixelFormat>(f.format);
  const AVPixFmtDescriptor* d = av_pix_fmt_desc_get(pix);
  if (!d) fail("unknown pixel format " + std::to_string(f.format));
  // Columns go in blocks of 8 from a multiple of 8, as in a full-width conversion, so a
  // crop gets exactly the pixels of the full picture (swscale's SIMD and C paths round
  // differently); rows start on a chroma row.
  const int ax = c.x & ~7, ay = c.y & ~((1 << d->log2_chroma_h) - 1);
  const int w = std::min((c.x + c.width - ax + 7) & ~7, f.width - ax);
  // Rows too: the 4:2:0 converters write rows in pairs.
  const int h = std::min((c.y + c.height - ay + 1) & ~1, f.height - ay);
  sws.reset(sws_getCachedContext(sws.release(), w, h, pix, w, h, AV_PIX_FMT_RGB24, SWS_BILINEAR,
                                 nullptr, nullptr, nullptr));
  if (!sws) fail(std::string("cannot convert ") + d->name + " to RGB");
  const bool full_range = f.color_range == AVCOL_RANGE_JPEG;
  const int* coeffs = sws_getCoefficients(sws_colorspace(f.colorspace));
  sws_setColorspaceDetails(sws.get(), coeffs, full_range, sws_getCoefficients(SWS_CS_DEFAULT), 1,
                           0, 1 << 16, 1 << 16);
  const std::uint8_t* src[4];
  plane_offsets(f, *d, ax, ay, src);
  // swscale's converters write whole blocks of 8 pixels and pairs of rows, past the end of
  // a crop of another size: such crops go through a padded scratch buffer.
  const bool direct =
      ax == c.x && ay == c.y && w == c.width && h == c.height && w % 16 == 0 && h % 2 == 0;
  const int stride = direct ? w * 3 : (w * 3 + 63) / 64 * 64 + 64;
  if (!direct) scratch.resize(static_cast<std::size_t>(stride) * (h + 2));
  std::uint8_t* dst[4] = {direct ? out : scratch.data(), nullptr, nullptr, nullptr};
  const int dst_stride[4] = {stride, 0, 0, 0};
  sws_scale(sws.get(), src, f.linesize, 0, h, dst, dst_stride);
  if (direct) return;
  const std::size_t dx = static_cast<std::size_t>(c.x - ax), dy = static_cast<std::size_t>(c.y - ay);
  const std::size_t row = static_cast<std::size_t>(c.width) * 3;
  for (int r = 0; r < c.height; ++r)
    std::copy_n(scratch.data() + (dy + r) * stride + dx * 3, row, out + r * row);
}

// Converts decoded frames on a second thread while the caller's thread keeps the decoder
// fed: with frame threading the decoder's workers then stay busy during conversions, and
// on two cores decoding plus conversion approach the decode-only speed.
class VideoReader::Impl::Converter {
 public:
  Converter(Impl& m, const Crop& c) : m_(m), crop_(c), thread_([this] { run(); }) {}
  ~Converter() { stop(); }
  // Queues a new reference to `f` (no copy of the pixels) for conversion into `dst`.
  void push(const AVFrame& f, std::uint8_t* dst) {
    av::Frame ref = av::alloc_frame<VideoDecodeError>(m_.path);
    BSP_AV_CHECK(VideoDecodeError, av_frame_ref(ref.get(), &f), m_.path, "reference a frame");
    std::unique_lock<std::mutex> lock(mu_);
    cv_.wait(lock, [&] { return jobs_.size() < kDepth || error_; });
    if (error_) std::rethrow_exception(error_);
    jobs_.push_back({std::move(ref), dst});
    cv_.notify_all();
  }
  // Waits for every queued conversion; rethrows the converter's error.
  void finish() {
    stop();
    if (error_) std::rethrow_exception(error_);
  }

 private:
  static constexpr std::size_t kDepth = 3;
  struct Job {
    av::Frame frame;
    std::uint8_t* dst;
  };
  void stop() {
    {
      std::lock_guard<std::mutex> lock(mu_);
      done_ = true;
      cv_.notify_all();
    }
    if (thread_.joinable()) thread_.join();
  }
  void run() {
    for (;;) {
      Job job;
      bool failed;
      {
        std::unique_lock<std::mutex> lock(mu_);
        cv_.wait(lock, [&] { return !jobs_.empty() || done_; });
        if (jobs_.empty()) return;
        job = std::move(jobs_.front());
        jobs_.pop_front();
        failed = error_ != nullptr;
        cv_.notify_all();
      }
      try {
        if (!failed) m_.convert(*job.frame, job.dst, crop_);
      } catch (...) {
        std::lock_guard<std::mutex> lock(mu_);
        error_ = std::current_exception();
        cv_.notify_all();
      }
    }
  }
  Impl& m_;
  Crop crop_;
  std::mutex mu_;
  std::condition_variable cv_;
  std::deque<Job> jobs_;
  bool done_ = false;
  std::exception_ptr error_;
  std::thread thread_;  // last: starts after the members it uses exist
};

VideoReader::VideoReader(std::string path, int threads) : impl_(std::make_unique<Impl>()) {
  impl_->path = std::move(path);
  if (threads < 0) impl_->fail("threads must be >= 0 (0 = one per core)");
  impl_->open(threads);
  impl_->scan();
}

VideoReader::~VideoReader() = default;

std::int64_t VideoReader::frame_count() const { return impl_->count; }
int VideoReader::width() const { return impl_->dec->width; }
int VideoReader::height() const { return impl_->dec->height; }
std::string VideoReader::codec() const { return impl_->dec->codec->name; }
const std::string& VideoReader::path() const { return impl_->path; }

double VideoReader::fps() const {
  const AVStream* st = impl_->fmt->streams[impl_->stream];
  AVRational r = st->avg_frame_rate;
  if (r.num <= 0 || r.den <= 0) r = st->r_frame_rate;
  return r.num > 0 && r.den > 0 ? av_q2d(r) : 0.0;
}

void VideoReader::read(const std::vector<std::int64_t>& indices, std::uint8_t* out,
                       const Crop& crop) {
  Impl& m = *impl_;
  const int W = width(), H = height();
  Crop c = crop;
  if (c.width == 0) c.width = W - c.x;
  if (c.height == 0) c.height = H - c.y;
  if (c.x < 0 || c.y < 0 || c.width <= 0 || c.height <= 0 || c.x + c.width > W || c.y + c.height > H)
    m.fail("crop " + std::to_string(c.width) + "x" + std::to_string(c.height) + "+" +
           std::to_string(c.x) + "+" + std::to_string(c.y) + " is outside the " +
           std::to_string(W) + "x" + std::to_string(H) + " picture");
  for (std::int64_t k : indices) {
    if (k < 0 || k >= m.count)
      m.fail("frame " + std::to_string(k) + " requested but file has " + std::to_string(m.count) +
             " frames" + (m.bad_reason.empty() ? "" : " (" + m.bad_reason + ")"));
    if (m.bad_frame >= 0 && k >= m.bad_frame) m.fail(m.at(k) + "cannot be decoded: " + m.bad_reason);
  }
  std::vector<std::size_t> order(indices.size());
  std::iota(order.begin(), order.end(), std::size_t{0});
  std::stable_sort(order.begin(), order.end(),
                   [&](std::size_t a, std::size_t b) { return indices[a] < indices[b]; });
  const std::size_t frame_bytes = static_cast<std::size_t>(c.width) * c.height * 3;
  std::lock_guard<std::mutex> lock(m.mutex);
  try {
    std::optional<Impl::Converter> pipeline;
    if (order.size() > 1) pipeline.emplace(m, c);
    for (std::size_t i = 0; i < order.size(); ++i) {
      if (i > 0 && indices[order[i]] == indices[order[i - 1]]) continue;  // copied below
      m.goto_frame(indices[order[i]]);
      if (pipeline)
        pipeline->push(*m.frame, out + order[i] * frame_bytes);
      else
        m.convert(*m.frame, out + order[i] * frame_bytes, c);
    }
    if (pipeline) pipeline->finish();
  } catch (...) {
    m.lost = true;
    throw;
  }
  for (std::size_t i = 1; i < order.size(); ++i)
    if (indices[order[i]] == indices[order[i - 1]])
      std::copy_n(out + order[i - 1] * frame_bytes, frame_bytes, out + order[i] * frame_bytes);
}

}  // namespace bsp
