// MP4/H.264 video: the writer used by the dataset generator and the reader used by the
// loaders. FFmpeg stays behind these classes (bsp/ffmpeg.hpp has the RAII wrappers).
#pragma once
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

namespace bsp {

// H.264 (High profile, yuv420p) in MP4 through libavcodec/libx264, x264 in average-bitrate
// mode like the original recorder. With threads = 1 the output is byte-identical for
// identical input (bit-exact muxer and codec flags, no wall-clock metadata). The file is
// written to "<path>.tmp-<pid>-<n>" and renamed to `path` by close(); a writer destroyed
// without close() removes its temporary file and leaves `path` untouched.
class VideoWriter {
 public:
  VideoWriter(std::string path, int width, int height, double fps = 30,
              std::int64_t bitrate = 1'000'000, std::string preset = "veryfast",
              int threads = 1);
  ~VideoWriter();
  VideoWriter(const VideoWriter&) = delete;
  VideoWriter& operator=(const VideoWriter&) = delete;

  // One frame of height*width*3 bytes, RGB, rows top to bottom.
  void write(const std::uint8_t* rgb);
  // Flushes the encoder, writes the trailer and renames the file into place. Idempotent.
  void close();

  std::int64_t frames_written() const;
  int width() const;
  int height() const;
  const std::string& path() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace bsp
