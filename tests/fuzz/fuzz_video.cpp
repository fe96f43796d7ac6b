// libFuzzer harness for the video reader (cpp/src/media/video_reader.cpp, FFmpeg behind
// it): the input is the file, opened as an MP4/MOV with the file protocol only. It reads
// the header, then a few frames out of order (a seek back to a keyframe) with and without
// a crop. Only VideoDecodeError is an expected answer. FFmpeg itself is the system's
// build, not instrumented: the harness checks our use of it (the packet scan, timestamps,
// seeking, the RGB conversion and crop) and catches FFmpeg reading past our buffers.
#include <algorithm>
#include <cstdint>
#include <cstdlib>
#include <vector>

#include "bsp/common/errors.hpp"
#include "bsp/media/video.hpp"
#include "fuzz_file.hpp"

namespace {
constexpr std::int64_t kMaxPixels = 1 << 18;  // decode only small pictures (fast executions)
}

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  static bsp::fuzz::MemFile file("input.mp4");
  const std::string& path = file.write(data, size);
  try {
    bsp::VideoReader v(path, /*threads=*/1);
    const std::int64_t n = v.frame_count();
    if (n <= 0 || v.width() <= 0 || v.height() <= 0) std::abort();
    (void)v.fps(), (void)v.codec();
    if (std::int64_t(v.width()) * v.height() > kMaxPixels) return 0;
    const std::size_t full = std::size_t(v.width()) * std::size_t(v.height()) * 3;
    std::vector<std::uint8_t> out(full * 3);
    try {
      v.read({n - 1, 0, n / 2}, out.data());
    } catch (const bsp::VideoDecodeError&) {
    }
    bsp::Crop crop;
    crop.x = v.width() / 4, crop.y = v.height() / 4;
    crop.width = std::max(1, v.width() / 2), crop.height = std::max(1, v.height() / 2);
    v.read({0}, out.data(), crop);
  } catch (const bsp::VideoDecodeError&) {
  }
  return 0;
}
