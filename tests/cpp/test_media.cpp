#include <doctest/doctest.h>

#include <algorithm>
#include <cstdio>
#include <cstring>
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
    CHECK(e.path().filename().string().rfind("." + fs::path(path).filename().string() + ".tmp-", 0) ==
          std::string::npos);
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

// ---------------------------------------------------------------- hostile files (issue 15)
namespace {

std::vector<std::uint8_t> file_bytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

void put_bytes(const std::string& path, const std::vector<std::uint8_t>& b) {
  std::ofstream(path, std::ios::binary)
      .write(reinterpret_cast<const char*>(b.data()), static_cast<std::streamsize>(b.size()));
}

// One PNG chunk: length, type, data, CRC.
std::vector<std::uint8_t> chunk(const char* type, const std::vector<std::uint8_t>& data) {
  std::vector<std::uint8_t> c(12 + data.size());
  png::put_u32(c.data(), static_cast<std::uint32_t>(data.size()));
  std::memcpy(c.data() + 4, type, 4);
  std::copy(data.begin(), data.end(), c.begin() + 8);
  png::put_u32(c.data() + 8 + data.size(),
               png::chunk_crc(c.data() + 4, c.data() + 8, data.size()));
  return c;
}

std::vector<std::uint8_t> ihdr(std::uint32_t w, std::uint32_t h, std::uint8_t colour_type = 3) {
  std::vector<std::uint8_t> d(13, 0);
  png::put_u32(d.data(), w);
  png::put_u32(d.data() + 4, h);
  d[8] = 8, d[9] = colour_type;
  return chunk("IHDR", d);
}

// Offset of the first chunk of `type` at or after `from` (chunk start, not its type).
std::size_t find_chunk(const std::vector<std::uint8_t>& b, const char* type, std::size_t from = 8) {
  for (std::size_t pos = 8; pos + 12 <= b.size(); pos += 12 + png::get_u32(b.data() + pos))
    if (pos >= from && std::memcmp(b.data() + pos + 4, type, 4) == 0) return pos;
  return std::string::npos;
}

// Recomputes the CRC of the chunk at `pos` after its data was edited.
void fix_crc(std::vector<std::uint8_t>& b, std::size_t pos) {
  const std::uint32_t len = png::get_u32(b.data() + pos);
  png::put_u32(b.data() + pos + 8 + len, png::chunk_crc(b.data() + pos + 4, b.data() + pos + 8, len));
}

std::string small_apng(int w, int h, int n) {
  const std::string path = temp_file("hostile.apng");
  ApngWriter wr(path, w, h, cityscapes_palette());
  for (int k = 0; k < n; ++k) wr.write(tags(k, w, h).data());
  wr.close();
  return path;
}

}  // namespace

TEST_CASE("apng: a second IHDR is refused at open, naming the file and the chunk") {
  const int w = 16, h = 10;
  const std::string path = small_apng(w, h, 4);
  std::vector<std::uint8_t> b = file_bytes(path);
  // A valid, larger IHDR just before frame 3's fcTL: frames 0..2 were sized for 16x10.
  std::size_t at = find_chunk(b, "fcTL");
  for (int k = 0; k < 3; ++k) at = find_chunk(b, "fcTL", at + 1);
  REQUIRE(at != std::string::npos);
  const std::vector<std::uint8_t> big = ihdr(64, 64);
  b.insert(b.begin() + static_cast<std::ptrdiff_t>(at), big.begin(), big.end());
  put_bytes(path, b);
  CHECK_THROWS_WITH_AS(ApngReader{path},
                       doctest::Contains((path + ": frame 2: second IHDR chunk at byte " +
                                          std::to_string(at)).c_str()),
                       ApngError);
  // The same IHDR right after the first one (before any frame) is refused too.
  b = file_bytes(small_apng(w, h, 2));
  const std::vector<std::uint8_t> same = ihdr(w, h);
  b.insert(b.begin() + 33, same.begin(), same.end());
  put_bytes(path, b);
  CHECK_THROWS_WITH_AS(ApngReader{path}, doctest::Contains("second IHDR chunk at byte 33"),
                       ApngError);
  fs::remove(path);
}

TEST_CASE("apng: an fcTL rectangle outside the canvas is an error naming the frame") {
  const int w = 16, h = 10;
  const std::string path = small_apng(w, h, 4);
  std::vector<std::uint8_t> b = file_bytes(path);
  std::size_t at = find_chunk(b, "fcTL");
  for (int k = 0; k < 2; ++k) at = find_chunk(b, "fcTL", at + 1);
  png::put_u32(b.data() + at + 8 + 12, 15);  // x_offset 15: one column left, any width overflows
  png::put_u32(b.data() + at + 8 + 4, 4);
  fix_crc(b, at);
  put_bytes(path, b);
  ApngReader rd(path);
  std::vector<std::uint8_t> out(static_cast<std::size_t>(w) * h * 3);
  CHECK_NOTHROW(rd.read({0, 1}, out.data()));
  CHECK_THROWS_WITH_AS(rd.read({2}, out.data()),
                       doctest::Contains((path + ": frame 2: fcTL region 4x").c_str()), ApngError);
  CHECK(rd.damage().find("frame 2: fcTL region 4x") == 0);
  fs::remove(path);
}

TEST_CASE("apng: decompression bombs are refused from the header, before any allocation") {
  const std::string path = temp_file("bomb.png");
  std::vector<std::uint8_t> b(png::kSignature, png::kSignature + 8);
  for (const auto& c : {ihdr(30000, 30000), chunk("PLTE", std::vector<std::uint8_t>(768, 0)),
                        chunk("IDAT", {0x78, 0x9c, 0x03, 0x00}), chunk("IEND", {})})
    b.insert(b.end(), c.begin(), c.end());
  put_bytes(path, b);
  CHECK_THROWS_WITH_AS(ApngReader{path},
                       doctest::Contains((path + ": image size 30000x30000 exceeds the limit").c_str()),
                       ApngError);
  // Within the limits the header alone allocates nothing: width() and height() can be
  // checked against what the caller expects before the first read() takes the canvas.
  b = std::vector<std::uint8_t>(png::kSignature, png::kSignature + 8);
  for (const auto& c : {ihdr(4096, 4096), chunk("PLTE", std::vector<std::uint8_t>(768, 0)),
                        chunk("IDAT", {0x78, 0x9c, 0x03, 0x00}), chunk("IEND", {})})
    b.insert(b.end(), c.begin(), c.end());
  put_bytes(path, b);
  ApngReader rd(path);
  CHECK(rd.width() == 4096);
  std::vector<std::uint8_t> one(std::size_t{4096} * 4096);
  CHECK_THROWS_WITH_AS(rd.read({0}, one.data()), doctest::Contains((path + ": frame 0: ").c_str()),
                       ApngError);
  // An acTL frame count no file could hold (delays() would size a vector by it).
  const std::string anim = small_apng(16, 10, 3);
  b = file_bytes(anim);
  const std::size_t actl = find_chunk(b, "acTL");
  png::put_u32(b.data() + actl + 8, 20'000'000);
  fix_crc(b, actl);
  b[find_chunk(b, "fdAT") + 9] ^= 0x10;  // damage: the open goes on past the frame count check
  put_bytes(anim, b);
  CHECK_THROWS_WITH_AS(ApngReader{anim},
                       doctest::Contains("acTL declares 20000000 frames, more than the limit"),
                       ApngError);
  fs::remove(path);
  fs::remove(anim);
}

TEST_CASE("video: a stream without a picture size is refused at open (found by fuzz_video)") {
  // The fuzzer's input: an MP4 whose H.264 stream parameters give a 0x0 picture; it opened
  // and reported width() == height() == 0.
  const std::string path = BSP_FUZZ_CORPUS_DIR "/video/found_zero_picture_size.mp4";
  REQUIRE(std::filesystem::exists(path));
  CHECK_THROWS_WITH_AS(VideoReader(path, 1),
                       doctest::Contains((path + ": the video stream has no valid picture size (0x0)").c_str()),
                       VideoDecodeError);
}
