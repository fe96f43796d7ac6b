// VideoWriter: RGB frames -> swscale -> libx264 -> MP4 muxer, through a temporary file.
#include <cmath>
#include <cstring>
#include <string>
#include <utility>

#include "bsp/common/errors.hpp"
#include "bsp/media/video.hpp"
#include "common/atomic_file.hpp"
#include "ffmpeg.hpp"

extern "C" {
#include <libavutil/cpu.h>
#include <libavutil/opt.h>
}

namespace bsp {
namespace {

// Muxer by the final name's extension ("clip.mp4" -> mp4), MP4 when it has none we know.
const AVOutputFormat* guess_format(const std::string& path) {
  const AVOutputFormat* f = av_guess_format(nullptr, path.c_str(), nullptr);
  return f ? f : av_guess_format("mp4", nullptr, nullptr);
}

// The rows' padding past the picture, which swscale leaves unwritten and x264 may read, is
// zero rather than whatever the allocator held.
void zero(AVFrame* f) {
  for (AVBufferRef* b : f->buf)
    if (b) std::memset(b->data, 0, b->size);
}

// x264's instruction sets for this CPU, AVX-512 left out. Debian's x264 (0.164.3095) gives
// different bytes for the same frames from one run to the next with its AVX-512 code (4 of
// 40 identical writes in one process on an avx512 EPYC, a dataset that bsp-synth made twice
// differed in one MP4); up to AVX2 it gave 64 of 64 identical files, the same bytes as its
// usual output there. Only sets the CPU has are named: x264 trusts the list.
std::string x264_asm() {
  const int f = av_get_cpu_flags();
  static const std::pair<int, const char*> sets[] = {
      {AV_CPU_FLAG_MMXEXT, "MMX2"}, {AV_CPU_FLAG_SSE, "SSE"},     {AV_CPU_FLAG_SSE2, "SSE2"},
      {AV_CPU_FLAG_SSE3, "SSE3"},   {AV_CPU_FLAG_SSSE3, "SSSE3"}, {AV_CPU_FLAG_SSE4, "SSE4.1"},
      {AV_CPU_FLAG_SSE42, "SSE4.2"}, {AV_CPU_FLAG_AVX, "AVX"},    {AV_CPU_FLAG_XOP, "XOP"},
      {AV_CPU_FLAG_FMA4, "FMA4"},   {AV_CPU_FLAG_FMA3, "FMA3"},   {AV_CPU_FLAG_BMI1, "BMI1"},
      {AV_CPU_FLAG_BMI1, "LZCNT"},  {AV_CPU_FLAG_BMI2, "BMI2"},   {AV_CPU_FLAG_AVX2, "AVX2"}};
  std::string out;
  for (const auto& [flag, name] : sets)
    if (f & flag) out += (out.empty() ? "" : ",") + std::string(name);
  return out.empty() ? "0" : out;  // "0": x264's C code only
}

}  // namespace

struct VideoWriter::Impl {
  std::string path;
  AtomicFile out;  // the temporary file, deleted unless close() renamed it into place
  int width = 0, height = 0;
  av::OutputFormat fmt;
  av::CodecContext enc;
  AVStream* stream = nullptr;
  av::Frame yuv;
  av::Packet pkt;
  av::Sws sws;
  std::int64_t frames = 0;
  bool closed = false;

  // An unfinished file never survives its writer: close the handle, then `out` deletes it.
  ~Impl() {
    enc.reset();
    fmt.reset();
  }
  [[noreturn]] void fail(const std::string& what) const { throw VideoEncodeError(path + ": " + what); }
  void open_encoder(double fps, std::int64_t bitrate, const std::string& preset, int threads);
  void open_muxer();
  void drain(bool flushing);
};

void VideoWriter::Impl::open_encoder(double fps, std::int64_t bitrate, const std::string& preset,
                                     int threads) {
  const AVCodec* codec = avcodec_find_encoder_by_name("libx264");
  if (!codec) fail("FFmpeg was built without the libx264 encoder");
  enc.reset(avcodec_alloc_context3(codec));
  if (!enc) fail("cannot allocate the encoder context");
  const AVRational rate = av_d2q(fps, 100000);
  enc->width = width;
  enc->height = height;
  enc->pix_fmt = AV_PIX_FMT_YUV420P;
  enc->time_base = av_inv_q(rate);
  enc->framerate = rate;
  enc->bit_rate = bitrate;  // x264 ABR, as the original recorder
  enc->thread_count = threads;
  // BT.601 limited range: what swscale's RGB->YUV produces, stated instead of implied.
  enc->color_range = AVCOL_RANGE_MPEG;
  enc->colorspace = AVCOL_SPC_SMPTE170M;
  enc->color_primaries = AVCOL_PRI_SMPTE170M;
  enc->color_trc = AVCOL_TRC_SMPTE170M;
  enc->flags |= AV_CODEC_FLAG_BITEXACT;
  if (fmt->oformat->flags & AVFMT_GLOBALHEADER) enc->flags |= AV_CODEC_FLAG_GLOBAL_HEADER;
  BSP_AV_CHECK(VideoEncodeError, av_opt_set(enc->priv_data, "preset", preset.c_str(), 0), path,
               "x264 preset '" + preset + "'");
  BSP_AV_CHECK(VideoEncodeError, av_opt_set(enc->priv_data, "profile", "high", 0), path,
               "x264 profile high");
  BSP_AV_CHECK(VideoEncodeError,
               av_opt_set(enc->priv_data, "x264-params", ("asm=" + x264_asm()).c_str(), 0),
               path, "x264 instruction sets");
  BSP_AV_CHECK(VideoEncodeError, avcodec_open2(enc.get(), codec, nullptr), path,
               "open libx264");
}

void VideoWriter::Impl::open_muxer() {
  stream = avformat_new_stream(fmt.get(), nullptr);
  if (!stream) fail("cannot add a video stream");
  BSP_AV_CHECK(VideoEncodeError, avcodec_parameters_from_context(stream->codecpar, enc.get()),
               path, "copy codec parameters");
  stream->time_base = enc->time_base;
  stream->avg_frame_rate = enc->framerate;
  if (!(fmt->oformat->flags & AVFMT_NOFILE))
    BSP_AV_CHECK(VideoEncodeError, avio_open(&fmt->pb, out.path().c_str(), AVIO_FLAG_WRITE),
                 path, "create " + out.path());
  BSP_AV_CHECK(VideoEncodeError, avformat_write_header(fmt.get(), nullptr), path,
               "write the container header");
}

// Moves every packet the encoder has ready into the muxer.
void VideoWriter::Impl::drain(bool flushing) {
  for (;;) {
    const int ret = avcodec_receive_packet(enc.get(), pkt.get());
    if (ret == AVERROR(EAGAIN) || (flushing && ret == AVERROR_EOF)) return;
    BSP_AV_CHECK(VideoEncodeError, ret, path, "frame " + std::to_string(frames) + ": encode");
    av_packet_rescale_ts(pkt.get(), enc->time_base, stream->time_base);
    pkt->stream_index = stream->index;
    BSP_AV_CHECK(VideoEncodeError, av_interleaved_write_frame(fmt.get(), pkt.get()), path,
                 "frame " + std::to_string(frames) + ": write packet");
  }
}

VideoWriter::VideoWriter(std::string path, int width, int height, double fps,
                         std::int64_t bitrate, std::string preset, int threads)
    : impl_(std::make_unique<Impl>()) {
  Impl& m = *impl_;
  m.path = std::move(path);
  m.width = width;
  m.height = height;
  if (width <= 0 || height <= 0 || width % 2 || height % 2)
    m.fail("yuv420p needs a positive even width and height, got " + std::to_string(width) +
           "x" + std::to_string(height));
  if (!(fps > 0) || !std::isfinite(fps)) m.fail("fps must be positive, got " + std::to_string(fps));
  if (bitrate <= 0) m.fail("bitrate must be positive, got " + std::to_string(bitrate));
  if (threads < 0) m.fail("threads must be >= 0 (0 = let x264 choose)");
  av::quiet_logs();
  m.out = AtomicFile(m.path);
  AVFormatContext* raw = nullptr;
  BSP_AV_CHECK(VideoEncodeError,
               avformat_alloc_output_context2(&raw, guess_format(m.path), nullptr,
                                              m.out.path().c_str()),
               m.path, "create the output context");
  m.fmt.reset(raw);
  m.fmt->flags |= AVFMT_FLAG_BITEXACT;  // no library versions or creation times in the file
  m.open_encoder(fps, bitrate, preset, threads);
  m.open_muxer();
  m.yuv = av::alloc_frame<VideoEncodeError>(m.path);
  m.yuv->format = AV_PIX_FMT_YUV420P;
  m.yuv->width = width;
  m.yuv->height = height;
  BSP_AV_CHECK(VideoEncodeError, av_frame_get_buffer(m.yuv.get(), 0), m.path, "frame buffer");
  zero(m.yuv.get());
  m.pkt = av::alloc_packet<VideoEncodeError>(m.path);
  m.sws.reset(sws_getContext(width, height, AV_PIX_FMT_RGB24, width, height, AV_PIX_FMT_YUV420P,
                             SWS_BICUBIC, nullptr, nullptr, nullptr));
  if (!m.sws) m.fail("cannot create the RGB->YUV converter");
}

VideoWriter::~VideoWriter() = default;

void VideoWriter::write(const std::uint8_t* rgb) {
  Impl& m = *impl_;
  if (m.closed) m.fail("write() after close()");
  const std::uint8_t* before = m.yuv->data[0];
  BSP_AV_CHECK(VideoEncodeError, av_frame_make_writable(m.yuv.get()), m.path, "frame buffer");
  if (m.yuv->data[0] != before) zero(m.yuv.get());
  const std::uint8_t* src[1] = {rgb};
  const int src_stride[1] = {3 * m.width};
  sws_scale(m.sws.get(), src, src_stride, 0, m.height, m.yuv->data, m.yuv->linesize);
  m.yuv->pts = m.frames;
  BSP_AV_CHECK(VideoEncodeError, avcodec_send_frame(m.enc.get(), m.yuv.get()), m.path,
               "frame " + std::to_string(m.frames) + ": send to encoder");
  m.drain(false);
  ++m.frames;
}

void VideoWriter::close() {
  Impl& m = *impl_;
  if (m.closed) return;
  BSP_AV_CHECK(VideoEncodeError, avcodec_send_frame(m.enc.get(), nullptr), m.path,
               "flush the encoder");
  m.drain(true);
  BSP_AV_CHECK(VideoEncodeError, av_write_trailer(m.fmt.get()), m.path, "write the trailer");
  m.fmt.reset();  // closes the file
  if (m.out.commit() != 0) m.fail("cannot rename " + m.out.path() + " into place");
  m.closed = true;
}

std::int64_t VideoWriter::frames_written() const { return impl_->frames; }
int VideoWriter::width() const { return impl_->width; }
int VideoWriter::height() const { return impl_->height; }
const std::string& VideoWriter::path() const { return impl_->path; }

}  // namespace bsp
