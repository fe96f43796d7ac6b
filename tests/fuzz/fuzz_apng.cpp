// libFuzzer harness for the APNG/PNG decoder (cpp/src/media/png_*.cpp, apng_reader.cpp):
// the input is the file. It opens it, asks every header question, maps video frames to
// APNG frames, then reads frames three ways: one at a time forward (the compositing and
// dispose paths), all of them in one request (the decode-ahead thread) and the last one
// again (seeking back to an independent frame). Only ApngError is an expected answer.
#include <algorithm>
#include <cstdint>
#include <cstdlib>
#include <vector>

#include "bsp/common/errors.hpp"
#include "bsp/media/apng.hpp"
#include "fuzz_file.hpp"

namespace {
// The converter compares width x height with the CSV's camera size before the first read
// and reads at most its camera size; the harness reads only small canvases so that an
// execution stays fast (the header-size checks run whatever the size).
constexpr std::size_t kMaxCanvasBytes = 1 << 20;
constexpr std::int64_t kMaxFrames = 24;
}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  static bsp::fuzz::MemFile file("input.apng");
  const std::string& path = file.write(data, size);
  try {
    bsp::ApngReader r(path);
    const std::int64_t n = r.frame_count();
    if (n < 0 || r.width() <= 0 || r.height() <= 0) std::abort();
    if (r.channels() < 1 || r.channels() > 4) std::abort();
    if (static_cast<std::int64_t>(r.delays().size()) != n) std::abort();
    for (double d : r.delays())
      if (!(d >= 0)) std::abort();
    (void)r.palette(), (void)r.dispose_ops(), (void)r.blend_ops(), (void)r.damage();
    (void)r.indexed(), (void)r.colour_type();
    const std::int64_t shown = std::min<std::int64_t>(n, kMaxFrames);
    for (std::int64_t k : r.video_to_apng_frames(shown + 2, 30.0))
      if (k < -1 || k >= n) std::abort();
    const std::size_t frame_bytes =
        std::size_t(r.width()) * std::size_t(r.height()) * std::size_t(r.channels());
    if (shown == 0 || frame_bytes > kMaxCanvasBytes) return 0;
    std::vector<std::uint8_t> out(frame_bytes * static_cast<std::size_t>(shown));
    try {
      for (std::int64_t k = 0; k < shown; ++k) r.read({k}, out.data());
    } catch (const bsp::ApngError&) {
    }
    std::vector<std::int64_t> all;
    for (std::int64_t k = shown - 1; k >= 0; --k) all.push_back(k);
    try {
      r.read(all, out.data());
    } catch (const bsp::ApngError&) {
    }
    r.read({shown - 1}, out.data());
  } catch (const bsp::ApngError&) {
  }
  return 0;
}
