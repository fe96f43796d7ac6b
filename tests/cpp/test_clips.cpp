// From rows to clips on a hand-made table: recordings, segments at frame gaps, windows,
// the in-image filter, labels, the split by recording and class balancing.
#include <doctest/doctest.h>

#include <algorithm>
#include <cstdint>
#include <stdexcept>
#include <tuple>
#include <vector>

#include "bsp/clips/clips.hpp"

using namespace bsp;

namespace {

// Rows of a table with one joint per row; keys() views them.
struct Table {
  std::vector<std::int32_t> id;
  std::vector<std::int64_t> cam, ped, frame, width, height;
  std::vector<std::uint8_t> crossing;
  std::vector<float> uv;
  void add(std::int32_t rec, std::int64_t f, bool cross = false, float u = 50) {
    id.push_back(rec), cam.push_back(0), ped.push_back(0), frame.push_back(f);
    width.push_back(100), height.push_back(100), crossing.push_back(cross);
    uv.push_back(u), uv.push_back(50);
  }
  RowKeys keys() const {
    return RowKeys{id.size(), id.data(), cam.data(), ped.data(), frame.data(),
                   crossing.data(), uv.data(), width.data(), height.data(), 1};
  }
};

// A: frames 0-4 and 6-11 (two segments; rows given newest first), crossing at 11.
// B: two rows (too short). C: frames 0-5, frame 4 outside the image. D: frames 0-8.
Table four_recordings() {
  Table t;
  for (std::int64_t f : {11, 10, 9, 8, 7, 6, 4, 3, 2, 1, 0}) t.add(0, f, f == 11);
  for (std::int64_t f : {0, 1}) t.add(1, f);
  for (std::int64_t f = 0; f < 6; ++f) t.add(2, f, false, f == 4 ? -1.0f : 50.0f);
  for (std::int64_t f = 0; f < 9; ++f) t.add(3, f);
  return t;
}

using ClipKey = std::tuple<std::uint32_t, std::uint32_t, std::int32_t, std::int32_t, int>;
std::vector<ClipKey> sorted(const std::vector<Clip>& clips) {
  std::vector<ClipKey> out;
  for (const Clip& c : clips) out.emplace_back(c.recording, c.first, c.segment, c.index, c.label);
  std::sort(out.begin(), out.end());
  return out;
}

ClipOptions length(int L) {
  ClipOptions o;
  o.length = L;
  return o;
}

}  // namespace

TEST_CASE("plan_clips by hand: segments, windows, in-image filter, labels, split") {
  const Table t = four_recordings();
  const Plan p = plan_clips(t.keys(), length(3));
  REQUIRE(p.recordings.size() == 4);
  CHECK(p.recordings[0].rows == std::vector<std::size_t>{10, 9, 8, 7, 6, 5, 4, 3, 2, 1, 0});
  CHECK(p.recordings[0].crosser);
  CHECK_FALSE(p.recordings[3].crosser);
  REQUIRE(p.skipped.size() == 1);
  CHECK(p.skipped[0].recording == 1);
  CHECK(p.skipped[0].reason == "shorter than min_video_length (2 < 3 rows)");
  CHECK(p.clips_rejected_out_of_image == 1);  // C's window over frames 3-5
  // Clips per split unit: A 3, C 1, D 3 -> test wants 1 and val 1 of the 7: A fills train,
  // C fits val, nothing fits test so it takes the next unit, D.
  CHECK(p.split_recordings[kTrain] == std::vector<std::uint32_t>{0});
  CHECK(p.split_recordings[kVal] == std::vector<std::uint32_t>{2});
  CHECK(p.split_recordings[kTest] == std::vector<std::uint32_t>{3});
  // (recording, first row of Recording::rows, segment, index in segment, label)
  CHECK(sorted(p.splits[kTrain]) == std::vector<ClipKey>{{0, 0, 0, 0, 0}, {0, 5, 1, 0, 0},
                                                          {0, 8, 1, 1, 1}});
  CHECK(sorted(p.splits[kVal]) == std::vector<ClipKey>{{2, 0, 0, 0, 0}});
  CHECK(sorted(p.splits[kTest]) == std::vector<ClipKey>{{3, 0, 0, 0, 0}, {3, 3, 0, 1, 0},
                                                        {3, 6, 0, 2, 0}});
  CHECK(p.clips_dropped_by_balance == 0);
}

TEST_CASE("plan_clips: the seed fixes the order, and balancing keeps as many of each class") {
  const Table t = four_recordings();
  ClipOptions o = length(3);
  const Plan a = plan_clips(t.keys(), o), b = plan_clips(t.keys(), o);
  REQUIRE(a.splits[kTest].size() == b.splits[kTest].size());
  for (std::size_t i = 0; i < a.splits[kTest].size(); ++i)
    CHECK(a.splits[kTest][i].first == b.splits[kTest][i].first);
  o.balance = true;
  const Plan bal = plan_clips(t.keys(), o);
  CHECK(bal.clips_dropped_by_balance == 1);
  REQUIRE(bal.splits[kTrain].size() == 2);
  CHECK(bal.splits[kTrain][0].label + bal.splits[kTrain][1].label == 1);
}

TEST_CASE("plan_clips: label_fraction looks at the last ceil(L * F) frames") {
  Table t;
  for (std::int64_t f = 0; f < 6; ++f) t.add(0, f, f == 1);
  ClipOptions o = length(3);
  CHECK(sorted(plan_clips(t.keys(), o).splits[kTrain]) ==
        std::vector<ClipKey>{{0, 0, 0, 0, 0}, {0, 3, 0, 1, 0}});
  o.label_fraction = 2.0 / 3;  // frames 1 and 2 of the first clip
  CHECK(sorted(plan_clips(t.keys(), o).splits[kTrain]) ==
        std::vector<ClipKey>{{0, 0, 0, 0, 1}, {0, 3, 0, 1, 0}});
}

TEST_CASE("plan_clips: benchmark windows carry their time to event (docs/hdf5-schema.md)") {
  // A crosses from frame 100 (event 100): frames 36..70 kept, windows every 6 from 36.
  // B never crosses (event 99 - 3 = 96, frames 32..66 kept) and lacks frame 50: windows
  // start at 32, 38, 44 in 32..49 and at 51, 57, 63 in 51..66.
  Table t;
  for (std::int64_t f = 0; f < 120; ++f) t.add(0, f, f >= 100);
  for (std::int64_t f = 0; f < 100; ++f)
    if (f != 50) t.add(1, f);
  ClipOptions o = length(4);
  o.stride = 6;
  o.benchmark = true;
  const Plan p = plan_clips(t.keys(), o);
  REQUIRE(p.recordings.size() == 2);
  CHECK(p.recordings[0].event_frame == 100);
  CHECK(p.recordings[1].event_frame == 96);
  std::vector<std::vector<std::int32_t>> tte(2);
  for (const auto& split : p.splits)
    for (const Clip& c : split) {
      const Recording& rec = p.recordings[c.recording];
      const std::int64_t last = t.frame[rec.rows[c.first + 3]];
      CHECK(c.time_to_event == rec.event_frame - last);
      tte[c.recording].push_back(c.time_to_event);
    }
  for (auto& v : tte) std::sort(v.begin(), v.end());
  // A: last frames 39, 45, ..., 69; B: 35, 41, 47 and 54, 60, 66 (the bound 30 included)
  CHECK(tte[0] == std::vector<std::int32_t>{31, 37, 43, 49, 55, 61});
  CHECK(tte[1] == std::vector<std::int32_t>{30, 36, 42, 49, 55, 61});
  o.benchmark = false;  // no event: every clip says so
  for (const auto& split : plan_clips(t.keys(), o).splits)
    for (const Clip& c : split) CHECK(c.time_to_event == kNoEvent);
}

TEST_CASE("plan_clips refuses bad options") {
  const Table t = four_recordings();
  CHECK_THROWS_AS(plan_clips(t.keys(), length(0)), std::invalid_argument);
  ClipOptions o = length(3);
  o.val_frac = 1.0;
  CHECK_THROWS_AS(plan_clips(t.keys(), o), std::invalid_argument);
  o = length(3);
  o.label_fraction = 1.5;
  CHECK_THROWS_AS(plan_clips(t.keys(), o), std::invalid_argument);
}

TEST_CASE("SplitMix64: the reference sequence, and below() stays in range") {
  SplitMix64 rng(0);
  CHECK(rng.next() == 0xE220A8397B1DCDAFull);
  CHECK(rng.next() == 0x6E789E6AA1B965F4ull);
  CHECK(rng.next() == 0x06C45D188009454Full);
  SplitMix64 r2(7);
  std::vector<int> seen(5, 0);
  for (int i = 0; i < 1000; ++i) ++seen[r2.below(5)];
  for (int s : seen) CHECK(s > 150);
}
