// Media conversion maths on hand-made frames: tag-4 statistics, joint visibility (radius 2
// around the rounded pixel), the square crop box and zero-padded crops.
#include <doctest/doctest.h>

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <vector>

#include "bsp/common/errors.hpp"
#include "bsp/conversion/convert.hpp"
#include "conversion/convert_internal.hpp"

using namespace bsp;

namespace {

// W x H road (tag 7) with a tag-4 rectangle [x0, x1) x [y0, y1).
std::vector<std::uint8_t> frame(int W, int H, int x0, int y0, int x1, int y1) {
  std::vector<std::uint8_t> f(static_cast<std::size_t>(W) * H, 7);
  for (int y = y0; y < y1; ++y)
    for (int x = x0; x < x1; ++x) f[static_cast<std::size_t>(y) * W + x] = kPedestrianTag;
  return f;
}

std::vector<float> joints_at(float u, float v) {
  std::vector<float> uv(52);
  for (int j = 0; j < 26; ++j) uv[2 * j] = u, uv[2 * j + 1] = v;
  return uv;
}

}  // namespace

TEST_CASE("frame_media: mask bbox, pixel count and per-joint visibility by hand") {
  const auto tags = frame(20, 16, 5, 4, 9, 12);  // pixels u 5..8, v 4..11
  auto uv = joints_at(6, 6);                     // inside the mask: visible
  auto set = [&](int j, float u, float v) { uv[2 * j] = u, uv[2 * j + 1] = v; };
  set(1, 10.4f, 8);   // rounds to (10, 8): mask pixel (8, 8) is 2 px away -> visible
  set(2, 11, 8);      // (11, 8): 3 px from the mask -> hidden
  set(3, 10.6f, 8);   // rounds up to 11 -> hidden
  set(4, 10, 13);     // (8, 11) is (2, 2) away: sqrt(8) > 2 -> hidden
  set(5, NAN, NAN);   // behind the camera: hidden, not in the bbox
  set(6, 2.5f, 4);    // halves round up: (3, 4) is 2 px from (5, 4) -> visible
  set(7, -1, 5);      // left of the image, 6 px from the mask -> hidden
  set(8, 9, 12);      // (8, 11) is (1, 1) away -> visible
  const FrameMedia m = frame_media(tags.data(), 20, 16, uv.data(), CropBoxPolicy::mask_joints);
  CHECK(m.mask_bbox == std::array<std::int32_t, 4>{5, 4, 9, 12});
  CHECK(m.visible_pixels == 32);
  const std::vector<int> hidden = {2, 3, 4, 5, 7};
  for (int j = 0; j < 26; ++j) {
    const bool h = std::find(hidden.begin(), hidden.end(), j) != hidden.end();
    CHECK_MESSAGE(m.joint_visible[j] == (h ? 0 : 1), "joint " << j);
  }
  // mask+joints: joints u -1..11, v 4..13 and mask [5, 9) x [4, 12): union 12 x 9 -> the 32 px minimum,
  // centre (5, 8.5): corner floor(5 - 16 + 0.5) = -11, floor(8.5 - 16 + 0.5) = -7.
  CHECK(m.crop_box == std::array<float, 4>{-11, -7, 21, 25});
}

TEST_CASE("frame_media: 20 % margin around a large mask, and no mask means nothing visible") {
  const auto tags = frame(200, 100, 50, 10, 90, 80);  // 40 x 70
  const auto uv = joints_at(60, 40);
  const FrameMedia m = frame_media(tags.data(), 200, 100, uv.data());
  CHECK(m.visible_pixels == 40 * 70);
  // side ceil(1.2 * 70) = 84 around (70, 45): corner (floor(28.5), floor(3.5)) = (28, 3).
  CHECK(m.crop_box == std::array<float, 4>{28, 3, 112, 87});

  const std::vector<std::uint8_t> empty(200 * 100, 7);
  auto spread = joints_at(100, 50);
  spread[0] = 20, spread[1] = 10;   // joint bbox 20..100 x 10..50: 80 x 40
  const FrameMedia e = frame_media(empty.data(), 200, 100, spread.data(), CropBoxPolicy::mask_joints);
  CHECK(e.mask_bbox == std::array<std::int32_t, 4>{-1, -1, -1, -1});
  CHECK(e.visible_pixels == 0);
  for (int j = 0; j < 26; ++j) CHECK(e.joint_visible[j] == 0);
  // side 96 around (60, 30): corner (floor(12.5), floor(-17.5)) = (12, -18).
  CHECK(e.crop_box == std::array<float, 4>{12, -18, 108, 78});
}

TEST_CASE("frame_media: the crop box policy (mask, mask+joints, joints) by hand") {
  const auto tags = frame(200, 100, 50, 10, 90, 80);  // mask [50, 90) x [10, 80): 40 x 70
  const auto uv = joints_at(40, 40);                   // every joint left of the mask
  // mask: side ceil(1.2 * 70) = 84 around (70, 45) -> corner (28, 3), the joints ignored
  CHECK(frame_media(tags.data(), 200, 100, uv.data(), CropBoxPolicy::mask).crop_box ==
        std::array<float, 4>{28, 3, 112, 87});
  // mask+joints: union u 40..90, v 10..80 (50 x 70): side 84 around (65, 45) -> (23, 3)
  CHECK(frame_media(tags.data(), 200, 100, uv.data(), CropBoxPolicy::mask_joints).crop_box ==
        std::array<float, 4>{23, 3, 107, 87});
  // joints: a point, so the 32 px minimum around (40, 40) -> (24, 24)
  CHECK(frame_media(tags.data(), 200, 100, uv.data(), CropBoxPolicy::joints).crop_box ==
        std::array<float, 4>{24, 24, 56, 56});
  // no pedestrian pixel: no crop under mask, the joints' box under the others
  const std::vector<std::uint8_t> empty(200 * 100, 7);
  const FrameMedia none = frame_media(empty.data(), 200, 100, uv.data(), CropBoxPolicy::mask);
  CHECK_FALSE(none.has_crop());
  for (float x : none.crop_box) CHECK(std::isnan(x));
  CHECK(frame_media(empty.data(), 200, 100, uv.data(), CropBoxPolicy::mask_joints).crop_box ==
        std::array<float, 4>{24, 24, 56, 56});
  CHECK(crop_box_policy("mask+joints") == CropBoxPolicy::mask_joints);
  CHECK(std::string(crop_box_name(CropBoxPolicy::joints)) == "joints");
  CHECK_THROWS_AS(crop_box_policy("union"), std::invalid_argument);
  // context 1.25 of an 84 px box: 105 px, corner moved by floor(21 / 2) = 10
  CHECK(context_box({28, 3, 112, 87}, 1.25) == std::array<float, 4>{18, -7, 123, 98});
  CHECK(context_size(128, 1.25) == 160);
}

TEST_CASE("crop_resize: zero padding outside the image, nearest and area resizing") {
  std::vector<std::uint8_t> img(16);
  for (int i = 0; i < 16; ++i) img[i] = static_cast<std::uint8_t>(i + 1);  // 4 x 4: 1..16
  std::vector<std::uint8_t> out(16);
  crop_resize(img.data(), 0, 0, 4, 4, 1, {-2, -1, 2, 3}, 4, true, out.data());
  CHECK(out == std::vector<std::uint8_t>{0, 0, 0, 0,  //
                                         0, 0, 1, 2,  //
                                         0, 0, 5, 6,  //
                                         0, 0, 9, 10});
  // The same crop from a region of the picture only (columns 0..1, rows 0..2).
  const std::vector<std::uint8_t> roi = {1, 2, 5, 6, 9, 10};
  std::vector<std::uint8_t> out2(16);
  crop_resize(roi.data(), 0, 0, 2, 3, 1, {-2, -1, 2, 3}, 4, true, out2.data());
  CHECK(out2 == out);
  // Area 4 -> 2: means of 2 x 2 blocks: (0+0+0+0)/4, (0+0+1+2)/4, 0, (5+6+9+10)/4.
  std::vector<std::uint8_t> half(4);
  crop_resize(img.data(), 0, 0, 4, 4, 1, {-2, -1, 2, 3}, 2, false, half.data());
  CHECK(half[0] == 0);
  CHECK(half[1] == 1);  // 0.75 rounds to 1
  CHECK(half[2] == 0);
  CHECK(half[3] == 8);  // 7.5 rounds to 8
  CHECK_THROWS_AS(crop_resize(img.data(), 0, 0, 4, 4, 1, {0, 0, 4, 3}, 2, false, half.data()), Error);
}

// ---- Shards of a distributed conversion (shard.cpp) ----------------------------------

namespace {

// A frame table of blocks of the given frame counts (recordings numbered from `rec0`),
// with `clips` clips of L = 2 frames pointing at rows 0, 1, 2, ...
detail::FrameTable table(std::vector<std::size_t> frames, std::uint32_t rec0, std::size_t clips) {
  detail::FrameTable t;
  t.begin.push_back(0);
  for (std::size_t b = 0; b < frames.size(); ++b) {
    t.recordings.push_back(rec0 + static_cast<std::uint32_t>(b));
    for (std::size_t f = 0; f < frames[b]; ++f) t.rows.push_back(100 * b + f);
    t.begin.push_back(t.rows.size());
  }
  for (std::size_t i = 0; i < clips * 2; ++i) t.clip_frames.push_back(static_cast<std::int64_t>(i));
  return t;
}

}  // namespace

TEST_CASE("shard_parts: clips and whole recordings cut into K runs that cover everything") {
  Plan plan;
  plan.splits[0].resize(7), plan.splits[1].resize(2), plan.splits[2].resize(3);
  // 70 frames: split 0 blocks of 10, 10, 10, 10; split 1 one of 5; split 2 of 20 and 5.
  const std::array<detail::FrameTable, 3> t = {table({10, 10, 10, 10}, 0, 7), table({5}, 4, 2),
                                               table({20, 5}, 5, 3)};
  const auto two0 = detail::shard_parts(plan, t, 0, 2), two1 = detail::shard_parts(plan, t, 1, 2);
  // blocks by frames: shard 0 starts before frame 35 (blocks starting at 0, 10, 20, 30)
  CHECK(two0.blocks[0] == std::make_pair<std::size_t, std::size_t>(0, 4));
  CHECK(two0.blocks[1] == std::make_pair<std::size_t, std::size_t>(0, 0));
  CHECK(two1.blocks[1] == std::make_pair<std::size_t, std::size_t>(0, 1));
  CHECK(two1.blocks[2] == std::make_pair<std::size_t, std::size_t>(0, 2));
  // clips: floor(N k / K)
  CHECK(two0.clips[0] == std::make_pair<std::size_t, std::size_t>(0, 3));
  CHECK(two1.clips[0] == std::make_pair<std::size_t, std::size_t>(3, 7));
  for (int K : {1, 3, 5, 9}) {
    for (int s = 0; s < 3; ++s) {
      std::size_t next_block = 0, next_clip = 0;
      for (int k = 0; k < K; ++k) {
        const auto p = detail::shard_parts(plan, t, k, K);
        CHECK(p.blocks[s].first == next_block);  // contiguous, in order, no gap or overlap
        CHECK(p.clips[s].first == next_clip);
        next_block = p.blocks[s].second, next_clip = p.clips[s].second;
      }
      CHECK(next_block == t[s].recordings.size());
      CHECK(next_clip == plan.splits[s].size());
    }
  }
  CHECK_THROWS_AS(detail::shard_parts(plan, t, 2, 2), std::invalid_argument);
}

TEST_CASE("slice_table: rows rebased per shard, clip_frames keep whole-table numbers") {
  const detail::FrameTable full = table({3, 4, 2}, 7, 4);
  const detail::FrameTable s = detail::slice_table(full, {1, 3}, {1, 3}, 2);
  CHECK(s.recordings == std::vector<std::uint32_t>{8, 9});
  CHECK(s.begin == std::vector<std::size_t>{0, 4, 6});
  CHECK(s.rows == std::vector<std::size_t>{100, 101, 102, 103, 200, 201});
  CHECK(s.clip_frames == std::vector<std::int64_t>{2, 3, 4, 5});
  const detail::FrameTable none = detail::slice_table(full, {2, 2}, {0, 0}, 2);
  CHECK(none.frames() == 0);
  CHECK(none.begin == std::vector<std::size_t>{0});
}
