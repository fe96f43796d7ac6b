// MP4/H.264 video: the writer used by the dataset generator and the reader used by the
// datasets. FFmpeg stays behind these classes (cpp/src/media/ffmpeg.hpp has the RAII
// wrappers).
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

// A rectangle of the picture in pixels; width or height 0 means the full picture.
struct Crop {
  int x = 0, y = 0, width = 0, height = 0;
};

// Decodes an MP4 (any FFmpeg-readable video) with libavcodec's threaded decoder. Frame k is
// the k-th frame displayed, counted from the first, after FFmpeg applies edit lists and
// B-frame reordering. The frame count is exact: it counts the packets that produce a shown
// frame (not the container's nb_frames); if decoding ends earlier, reads past the end
// throw. read() decodes sequentially (seeking to a keyframe only to skip ahead or go back)
// and converts only the requested frames, cropping before the colour conversion.
// Decoding errors throw VideoDecodeError naming the file and the frame. Not thread-safe
// per object (read() takes a lock); use one reader per thread or process.
class VideoReader {
 public:
  // threads: decoder threads; 0 = cores + 2 (frame threading plus the converter thread).
  explicit VideoReader(std::string path, int threads = 0);
  ~VideoReader();
  VideoReader(const VideoReader&) = delete;
  VideoReader& operator=(const VideoReader&) = delete;

  std::int64_t frame_count() const;
  double fps() const;  // average frame rate of the stream
  int width() const;
  int height() const;
  std::string codec() const;
  const std::string& path() const;

  // Frames `indices` (any order, repeats allowed) as RGB24, cropped to `crop`, into `out`
  // of indices.size() * crop height * crop width * 3 bytes.
  void read(const std::vector<std::int64_t>& indices, std::uint8_t* out, const Crop& crop = {});

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace bsp
