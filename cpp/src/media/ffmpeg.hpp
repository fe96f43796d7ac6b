// RAII for FFmpeg: every libav* object lives in a std::unique_ptr whose deleter calls the
// matching free function, so no early return or exception can leak a context. All error
// codes go through av_check()/BSP_AV_CHECK, which throw the caller's typed exception with
// the file, what was being done and av_strerror's text.
#pragma once
#include <memory>
#include <mutex>
#include <string>

extern "C" {
#include <libavcodec/avcodec.h>
#include <libavformat/avformat.h>
#include <libavutil/error.h>
#include <libavutil/frame.h>
#include <libavutil/log.h>
#include <libswscale/swscale.h>
}

namespace bsp::av {

struct InputFormatDeleter {
  void operator()(AVFormatContext* p) const noexcept { avformat_close_input(&p); }
};
// An output context owns its AVIOContext only when the format writes to a file.
struct OutputFormatDeleter {
  void operator()(AVFormatContext* p) const noexcept {
    if (p->oformat && !(p->oformat->flags & AVFMT_NOFILE)) avio_closep(&p->pb);
    avformat_free_context(p);
  }
};
struct CodecContextDeleter {
  void operator()(AVCodecContext* p) const noexcept { avcodec_free_context(&p); }
};
struct FrameDeleter {
  void operator()(AVFrame* p) const noexcept { av_frame_free(&p); }
};
struct PacketDeleter {
  void operator()(AVPacket* p) const noexcept { av_packet_free(&p); }
};
struct SwsDeleter {
  void operator()(SwsContext* p) const noexcept { sws_freeContext(p); }
};

using InputFormat = std::unique_ptr<AVFormatContext, InputFormatDeleter>;
using OutputFormat = std::unique_ptr<AVFormatContext, OutputFormatDeleter>;
using CodecContext = std::unique_ptr<AVCodecContext, CodecContextDeleter>;
using Frame = std::unique_ptr<AVFrame, FrameDeleter>;
using Packet = std::unique_ptr<AVPacket, PacketDeleter>;
using Sws = std::unique_ptr<SwsContext, SwsDeleter>;

// av_strerror's text for an AVERROR code.
inline std::string error_text(int err) {
  char buf[AV_ERROR_MAX_STRING_SIZE] = {0};
  if (av_strerror(err, buf, sizeof buf) < 0) return "error code " + std::to_string(err);
  return buf;
}

// Returns `ret` when it is not an error; otherwise throws E("<file>: <what>: <reason>").
template <class E>
int av_check(int ret, const std::string& file, const std::string& what) {
  if (ret < 0) throw E(file + ": " + what + ": " + error_text(ret));
  return ret;
}

// libx264 and the decoders print banners and statistics at FFmpeg's default INFO level;
// our errors travel as exceptions instead. Lowered once, and only if nobody (PyAV, the
// application) has chosen a level already.
inline void quiet_logs() {
  static std::once_flag once;
  std::call_once(once, [] {
    // FFmpeg's own lines never reach stderr (bsp-convert --quiet must be quiet): every
    // failure is reported by our exceptions, with av_strerror's text. A level someone set
    // on purpose (not the library default) is left alone.
    if (av_log_get_level() == AV_LOG_INFO) av_log_set_level(AV_LOG_QUIET);
  });
}

// Allocation helpers that throw instead of returning null.
template <class E>
Frame alloc_frame(const std::string& file) {
  Frame f(av_frame_alloc());
  if (!f) throw E(file + ": cannot allocate an AVFrame");
  return f;
}
template <class E>
Packet alloc_packet(const std::string& file) {
  Packet p(av_packet_alloc());
  if (!p) throw E(file + ": cannot allocate an AVPacket");
  return p;
}

}  // namespace bsp::av

// BSP_AV_CHECK(VideoDecodeError, avcodec_send_packet(c, p), file_, "frame 12: send packet")
#define BSP_AV_CHECK(ErrorType, call, file, what) ::bsp::av::av_check<ErrorType>((call), (file), (what))
