#include <doctest/doctest.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <random>
#include <string>
#include <vector>

#include "bsp/common/errors.hpp"
#include "bsp/media/apng.hpp"
#include "bsp/media/video.hpp"
#include "media/png.hpp"  // white-box: PNG filters and blending

using namespace bsp;
namespace fs = std::filesystem;

namespace {

std::string temp_file(const std::string& name) {
  static std::random_device rd;
  return (fs::temp_directory_path() / ("bsp_media_" + std::to_string(rd()) + "_" + name)).string();
}

std::vector<std::uint8_t> unfiltered(std::uint8_t type, std::vector<std::uint8_t> row,
                                     const std::vector<std::uint8_t>* prev, std::size_t bpp) {
  REQUIRE(png::unfilter_row(type, row.data(), prev ? prev->data() : nullptr, row.size(), bpp));
  return row;
}

// Frame k: road and sky, a 3x6 "pedestrian" (tag 4) walking right; frames 3..5 identical.
std::vector<std::uint8_t> tags(int k, int w, int h) {
  std::vector<std::uint8_t> f(static_cast<std::size_t>(w) * h);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) f[y * w + x] = y < h / 2 ? 13 : 7;
  const int step = k < 3 ? k : (k <= 5 ? 3 : k - 2);
  for (int y = 2; y < 8; ++y)
    for (int x = 0; x < 3; ++x) f[y * w + 1 + 2 * step + x] = 4;
  return f;
}

}  // namespace

TEST_CASE("png unfilter: each filter type on hand-made rows") {
  const std::vector<std::uint8_t> f = {1, 2, 3, 4}, up = {10, 20, 30, 40};
  CHECK(unfiltered(png::kNone, f, &up, 1) == std::vector<std::uint8_t>{1, 2, 3, 4});
  CHECK(unfiltered(png::kSub, f, &up, 1) == std::vector<std::uint8_t>{1, 3, 6, 10});
  CHECK(unfiltered(png::kUp, f, &up, 1) == std::vector<std::uint8_t>{11, 22, 33, 44});
  // Average: f + floor((left + up) / 2): 1+5, 2+13, 3+22, 4+32.
  CHECK(unfiltered(png::kAverage, f, &up, 1) == std::vector<std::uint8_t>{6, 15, 25, 36});
  // Paeth picks up, left, up, then upper-left: 1+10, 2+11, 216+50 (mod 256), 4+50.
  const std::vector<std::uint8_t> pf = {1, 2, 216, 4}, pu = {10, 10, 50, 100};
  CHECK(unfiltered(png::kPaeth, pf, &pu, 1) == std::vector<std::uint8_t>{11, 13, 10, 54});
  // Three bytes per pixel: Sub adds the same channel of the pixel to the left.
  CHECK(unfiltered(png::kSub, {1, 2, 3, 4, 5, 6}, nullptr, 3) ==
        std::vector<std::uint8_t>{1, 2, 3, 5, 7, 9});
  // First row (no row above): Up is a no-op, Paeth acts as Sub.
  CHECK(unfiltered(png::kUp, f, nullptr, 1) == f);
  CHECK(unfiltered(png::kPaeth, f, nullptr, 1) == std::vector<std::uint8_t>{1, 3, 6, 10});
  std::vector<std::uint8_t> row = f;
  CHECK_FALSE(png::unfilter_row(5, row.data(), nullptr, row.size(), 1));
}

TEST_CASE("png filter_row inverts unfilter_row for every type") {
  std::mt19937 rng(3);
  for (std::size_t bpp : {1, 2, 3, 4}) {
    std::vector<std::uint8_t> prev(48), row(48), out(48);
    for (auto& v : prev) v = static_cast<std::uint8_t>(rng());
    for (auto& v : row) v = static_cast<std::uint8_t>(rng());
    for (std::uint8_t t = 0; t <= 4; ++t) {
      for (const std::vector<std::uint8_t>* p : {&prev, static_cast<decltype(&prev)>(nullptr)}) {
        png::filter_row(t, row.data(), p ? p->data() : nullptr, row.size(), bpp, out.data());
        CHECK(unfiltered(t, out, p, bpp) == row);
      }
    }
  }
}

TEST_CASE("png blend OVER matches hand-computed Porter-Duff values") {
  std::vector<std::uint8_t> dst = {100, 50, 0, 255, 100, 50, 0, 100, 1, 2, 3, 4, 9, 9, 9, 9};
  const std::vector<std::uint8_t> src = {200, 100, 50, 128, 200, 100, 50, 128,
                                         7, 7, 7, 0, 5, 6, 7, 255};
  png::blend_over_alpha(dst.data(), src.data(), 4, 4);
  // Opaque background: round((a*s + (255-a)*d) / 255); translucent: the full formula.
  CHECK(dst == std::vector<std::uint8_t>{150, 75, 25, 255, 171, 85, 35, 178, 1, 2, 3, 4, 5, 6, 7, 255});
}

TEST_CASE("apng: write -> read round trip with sub-rectangles and dropped duplicates") {
  const int w = 24, h = 12, n = 9;
  for (bool drop : {false, true}) {
    const std::string path = temp_file("rt.apng");
    {
      ApngWriter wr(path, w, h, cityscapes_palette(), 30, drop);
      for (int k = 0; k < n; ++k) wr.write(tags(k, w, h).data());
      wr.close();
      CHECK(wr.frames_written() == n);
      CHECK(wr.frames_stored() == (drop ? n - 2 : n));
    }
    ApngReader rd(path);
    REQUIRE(rd.frame_count() == (drop ? n - 2 : n));
    CHECK(rd.indexed());
    CHECK(rd.width() == w);
    CHECK(rd.palette().size() == 768);
    CHECK(rd.palette()[3 * 4] == 220);  // Pedestrian red
    const std::vector<std::int64_t> map = rd.video_to_apng_frames(n, 30);
    std::vector<std::uint8_t> got(static_cast<std::size_t>(n) * w * h);
    rd.read(map, got.data());
    for (int k = 0; k < n; ++k) {
      const auto want = tags(k, w, h);
      CHECK(std::equal(want.begin(), want.end(), got.begin() + static_cast<std::ptrdiff_t>(k) * w * h));
    }
    const std::vector<double> d = rd.delays();
    CHECK(d[0] == doctest::Approx(1.0 / 30));
    if (drop) CHECK(d[3] == doctest::Approx(3.0 / 30));  // frames 3, 4, 5 shown as one
    CHECK_THROWS_WITH_AS(rd.read({n}, got.data()),
                         doctest::Contains("requested but file has"), ApngError);
    fs::remove(path);
  }
}

TEST_CASE("apng: a flipped byte is reported as a bad CRC naming the chunk and frame") {
  const int w = 16, h = 10;
  const std::string path = temp_file("crc.apng");
  {
    ApngWriter wr(path, w, h, cityscapes_palette());
    for (int k = 0; k < 4; ++k) wr.write(tags(k, w, h).data());
    wr.close();
  }
  std::ifstream in(path, std::ios::binary);
  std::vector<char> bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  in.close();
  // The last fdAT belongs to frame 3; flip a byte inside its data.
  std::string s(bytes.begin(), bytes.end());
  const std::size_t at = s.rfind("fdAT");
  REQUIRE(at != std::string::npos);
  bytes[at + 9] ^= 0x10;
  std::ofstream(path, std::ios::binary).write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  ApngReader rd(path);
  std::vector<std::uint8_t> out(static_cast<std::size_t>(w) * h * 3);
  CHECK_NOTHROW(rd.read({0, 1, 2}, out.data()));
  CHECK_THROWS_WITH_AS(rd.read({3}, out.data()), doctest::Contains("frame 3: bad CRC in chunk fdAT"),
                       ApngError);
  fs::remove(path);
}

TEST_CASE("apng writer: a writer dropped without close leaves no file") {
  const std::string path = temp_file("gone.apng");
  {
    ApngWriter wr(path, 8, 8, cityscapes_palette());
    wr.write(std::vector<std::uint8_t>(64, 7).data());
  }
  CHECK_FALSE(fs::exists(path));
  for (const auto& e : fs::directory_iterator(fs::temp_directory_path()))
    CHECK(e.path().string().find(path + ".tmp-") == std::string::npos);
}

TEST_CASE("video: write -> read round trip keeps count, size and picture") {
  const int w = 64, h = 48, n = 20;
  const std::string path = temp_file("rt.mp4");
  {
    VideoWriter wr(path, w, h);
    std::vector<std::uint8_t> rgb(static_cast<std::size_t>(w) * h * 3);
    for (int k = 0; k < n; ++k) {
      for (std::size_t i = 0; i < rgb.size(); ++i) rgb[i] = static_cast<std::uint8_t>(k * 10);
      wr.write(rgb.data());
    }
    wr.close();
  }
  VideoReader rd(path, 1);
  CHECK(rd.frame_count() == n);
  CHECK(rd.width() == w);
  CHECK(rd.fps() == doctest::Approx(30));
  std::vector<std::uint8_t> out(static_cast<std::size_t>(w) * h * 3 * 2);
  rd.read({15, 2}, out.data());
  CHECK(std::abs(int(out[w * h * 3 / 2]) - 150) <= 3);               // frame 15, grey 150
  CHECK(std::abs(int(out[w * h * 3 + w * h * 3 / 2]) - 20) <= 3);    // frame 2, grey 20
  CHECK_THROWS_WITH_AS(rd.read({20}, out.data()),
                       doctest::Contains("frame 20 requested but file has 20 frames"),
                       VideoDecodeError);
  fs::remove(path);
}
