#include "bsp/clips/clips.hpp"

#include <algorithm>
#include <cmath>
#include <map>
#include <numeric>
#include <stdexcept>
#include <tuple>

namespace bsp {

std::uint64_t SplitMix64::next() {
  std::uint64_t z = (s_ += 0x9E3779B97F4A7C15ull);
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
  return z ^ (z >> 31);
}

std::uint64_t SplitMix64::below(std::uint64_t n) {
  // Rejection sampling: unbiased and identical on every platform.
  const std::uint64_t limit = UINT64_MAX - UINT64_MAX % n;
  std::uint64_t x;
  do x = next();
  while (x >= limit);
  return x % n;
}

namespace {

struct Resolved {
  int L, stride, eval_stride, min_len, tail;  // tail: frames looked at by the label rule
};

Resolved resolve(const ClipOptions& o) {
  Resolved r{o.length, o.stride ? o.stride : o.length, 0, 0, 1};
  r.eval_stride = o.eval_stride ? o.eval_stride : r.stride;
  r.min_len = o.min_video_length ? o.min_video_length : r.L;
  if (r.L <= 0 || r.stride <= 0 || r.eval_stride <= 0 || r.min_len < 0)
    throw std::invalid_argument("clip length and strides must be positive");
  if (!(o.val_frac >= 0 && o.test_frac >= 0 && o.val_frac < 1 && o.test_frac < 1))
    throw std::invalid_argument("val/test fractions must lie in [0, 1)");
  if (o.label_fraction < 0 || o.label_fraction > 1)
    throw std::invalid_argument("label fraction must lie in (0, 1]");
  if (o.label_fraction > 0) r.tail = static_cast<int>(std::ceil(r.L * o.label_fraction - 1e-9));
  r.tail = std::clamp(r.tail, 1, r.L);
  return r;
}

std::vector<Recording> group_recordings(const RowKeys& k) {
  std::map<std::tuple<std::int32_t, std::int64_t, std::int64_t>, std::size_t> index;
  std::vector<Recording> recs;
  for (std::size_t r = 0; r < k.rows; ++r) {
    auto key = std::make_tuple(k.id_code[r], k.camera_idx[r], k.pedestrian_idx[r]);
    auto [it, fresh] = index.emplace(key, recs.size());
    if (fresh) {
      recs.emplace_back();
      recs.back().id_code = k.id_code[r];
      recs.back().camera_idx = k.camera_idx[r];
      recs.back().pedestrian_idx = k.pedestrian_idx[r];
    }
    recs[it->second].rows.push_back(r);
  }
  for (auto& rec : recs) {
    std::stable_sort(rec.rows.begin(), rec.rows.end(), [&](std::size_t a, std::size_t b) {
      return k.frame_idx[a] < k.frame_idx[b];
    });
    for (std::size_t r : rec.rows) rec.crosser = rec.crosser || k.is_crossing[r];
  }
  return recs;
}

// Row lies fully inside its image: every joint finite and 0 <= u <= W, 0 <= v <= H.
std::vector<std::uint8_t> rows_inside(const RowKeys& k) {
  std::vector<std::uint8_t> in(k.rows);
  for (std::size_t r = 0; r < k.rows; ++r) {
    const float* p = k.pose_camera + r * static_cast<std::size_t>(k.joints) * 2;
    const double W = static_cast<double>(k.width[r]), H = static_cast<double>(k.height[r]);
    bool ok = true;
    for (int j = 0; ok && j < k.joints; ++j) {
      const double u = p[2 * j], v = p[2 * j + 1];
      ok = std::isfinite(u) && std::isfinite(v) && u >= 0 && u <= W && v >= 0 && v <= H;
    }
    in[r] = ok;
  }
  return in;
}

struct Candidates {
  std::size_t begin = 0, end = 0;  // range of Recording::rows considered
  std::string skip;                // non-empty: why the recording yields nothing
};

Candidates candidates(const RowKeys& k, Recording& rec, const Resolved& r, bool benchmark) {
  Candidates c{0, rec.rows.size(), ""};
  if (!benchmark) {
    if (rec.rows.size() < static_cast<std::size_t>(r.min_len))
      c.skip = "shorter than min_video_length (" + std::to_string(rec.rows.size()) + " < " +
               std::to_string(r.min_len) + " rows)";
    return c;
  }
  if (rec.rows.size() < static_cast<std::size_t>(r.L + 60)) {
    c.skip = "benchmark needs >= L + 60 = " + std::to_string(r.L + 60) + " rows, has " +
             std::to_string(rec.rows.size());
    return c;
  }
  rec.event_frame = k.frame_idx[rec.rows.back()] - 3;
  for (std::size_t r0 : rec.rows)
    if (k.is_crossing[r0]) {
      rec.event_frame = k.frame_idx[r0];
      break;
    }
  const std::int64_t lo = rec.event_frame - r.L - 60, hi = rec.event_frame - 30;
  while (c.begin < c.end && k.frame_idx[rec.rows[c.begin]] < lo) ++c.begin;
  while (c.end > c.begin && k.frame_idx[rec.rows[c.end - 1]] > hi) --c.end;
  return c;
}

std::uint8_t clip_label(const RowKeys& k, const Recording& rec, std::size_t first,
                        const Resolved& r, bool benchmark) {
  if (benchmark) return rec.crosser;
  for (int i = r.L - r.tail; i < r.L; ++i)
    if (k.is_crossing[rec.rows[first + static_cast<std::size_t>(i)]]) return 1;
  return 0;
}

// Windows of L rows every `stride` inside contiguous segments of [c.begin, c.end).
// Returns the clips that pass the in-image filter; counts rejected ones.
std::vector<Clip> slice(const RowKeys& k, const Recording& rec, std::uint32_t rec_index,
                        const Candidates& c, int stride, const Resolved& r, bool benchmark,
                        const std::vector<std::uint8_t>& inside, std::size_t& rejected) {
  std::vector<Clip> out;
  std::int32_t segment = 0;
  std::size_t seg_begin = c.begin;
  for (std::size_t i = c.begin; i < c.end; ++i) {
    const bool last = i + 1 == c.end ||
                      k.frame_idx[rec.rows[i + 1]] != k.frame_idx[rec.rows[i]] + 1;
    if (!last) continue;
    const std::size_t seg_len = i + 1 - seg_begin;
    std::int32_t index = 0;
    for (std::size_t s = 0; s + static_cast<std::size_t>(r.L) <= seg_len; s += stride, ++index) {
      const std::size_t first = seg_begin + s;
      bool ok = true;
      for (int f = 0; ok && f < r.L; ++f) ok = inside[rec.rows[first + static_cast<std::size_t>(f)]];
      if (!ok) {
        ++rejected;
        continue;
      }
      Clip clip{rec_index, static_cast<std::uint32_t>(first), segment, index,
                clip_label(k, rec, first, r, benchmark)};
      if (benchmark) {
        const std::int64_t last_frame = k.frame_idx[rec.rows[first + static_cast<std::size_t>(r.L) - 1]];
        clip.time_to_event = static_cast<std::int32_t>(rec.event_frame - last_frame);
      }
      out.push_back(clip);
    }
    ++segment;
    seg_begin = i + 1;
  }
  return out;
}

// docs/dataset-format.md, "7. From rows to clips and splits": fill train, val, test in
// turn with the next unit that fits what each still needs; an empty set takes the next unit
// anyway; when no set can take one, the rest goes to train.
std::vector<int> assign_units(const std::vector<std::size_t>& counts, const ClipOptions& o) {
  const std::size_t n_units = counts.size();
  std::vector<std::size_t> order(n_units);
  std::iota(order.begin(), order.end(), 0);
  std::stable_sort(order.begin(), order.end(),
                   [&](std::size_t a, std::size_t b) { return counts[a] > counts[b]; });
  const auto N = static_cast<std::int64_t>(std::accumulate(counts.begin(), counts.end(), std::size_t{0}));
  const std::int64_t test = std::max<std::int64_t>(static_cast<std::int64_t>(std::floor(o.test_frac * N)), 1);
  const std::int64_t val = std::max<std::int64_t>(static_cast<std::int64_t>(std::floor(o.val_frac * (N - test))), 1);
  std::array<std::int64_t, 3> need = {N - test - val, val, test};
  std::array<std::size_t, 3> taken = {0, 0, 0};
  std::vector<int> split(n_units, kTrain);
  std::vector<std::size_t> left(order);
  while (!left.empty()) {
    bool progressed = false;
    for (int s = 0; s < 3 && !left.empty(); ++s) {
      auto it = std::find_if(left.begin(), left.end(), [&](std::size_t u) {
        return static_cast<std::int64_t>(counts[u]) <= need[s];
      });
      if (it == left.end() && taken[s] == 0) it = left.begin();
      if (it == left.end()) continue;
      split[*it] = s, need[s] -= static_cast<std::int64_t>(counts[*it]), ++taken[s];
      left.erase(it);
      progressed = true;
    }
    if (!progressed) break;  // the rest stays in train
  }
  return split;
}

void shuffle(std::vector<Clip>& clips, SplitMix64& rng) {
  for (std::size_t i = clips.size(); i > 1; --i) std::swap(clips[i - 1], clips[rng.below(i)]);
}

std::size_t balance(std::vector<Clip>& clips) {
  std::array<std::size_t, 2> count = {0, 0};
  for (const Clip& c : clips) ++count[c.label ? 1 : 0];
  const std::size_t keep = std::min(count[0], count[1]);
  std::array<std::size_t, 2> kept = {0, 0};
  std::vector<Clip> out;
  for (const Clip& c : clips)
    if (kept[c.label ? 1 : 0]++ < keep) out.push_back(c);
  const std::size_t dropped = clips.size() - out.size();
  clips.swap(out);
  return dropped;
}

}  // namespace

Plan plan_clips(const RowKeys& k, const ClipOptions& o) {
  const Resolved r = resolve(o);
  Plan plan;
  plan.recordings = group_recordings(k);
  const std::vector<std::uint8_t> inside = rows_inside(k);
  const auto n_rec = plan.recordings.size();
  std::vector<Candidates> cand(n_rec);
  std::vector<std::vector<Clip>> train_clips(n_rec);
  // Split units are (id, camera.idx) in first-appearance order.
  std::map<std::pair<std::int32_t, std::int64_t>, std::size_t> unit_of;
  std::vector<std::size_t> unit(n_rec), counts;
  std::size_t rejected = 0;
  for (std::uint32_t i = 0; i < n_rec; ++i) {
    Recording& rec = plan.recordings[i];
    cand[i] = candidates(k, rec, r, o.benchmark);
    if (cand[i].skip.empty()) {
      train_clips[i] = slice(k, rec, i, cand[i], r.stride, r, o.benchmark, inside, rejected);
      if (train_clips[i].empty())
        cand[i].skip = "no window of " + std::to_string(r.L) +
                       " contiguous frames lies fully inside the image";
    }
    if (!cand[i].skip.empty()) {
      plan.skipped.push_back({i, cand[i].skip});
      continue;
    }
    auto [it, fresh] = unit_of.emplace(std::make_pair(rec.id_code, rec.camera_idx), counts.size());
    if (fresh) counts.push_back(0);
    unit[i] = it->second;
    counts[it->second] += train_clips[i].size();
  }
  const std::vector<int> unit_split = assign_units(counts, o);
  std::size_t ignored = 0;
  for (std::uint32_t i = 0; i < n_rec; ++i) {
    if (!cand[i].skip.empty()) continue;
    const int s = unit_split[unit[i]];
    plan.split_recordings[s].push_back(i);
    auto clips = s == kTrain ? std::move(train_clips[i])
                             : slice(k, plan.recordings[i], i, cand[i], r.eval_stride, r,
                                     o.benchmark, inside, ignored);
    plan.splits[s].insert(plan.splits[s].end(), clips.begin(), clips.end());
  }
  plan.clips_rejected_out_of_image = rejected;
  SplitMix64 rng(o.seed);
  for (auto& clips : plan.splits) shuffle(clips, rng);
  if (o.balance) plan.clips_dropped_by_balance = balance(plan.splits[kTrain]);
  return plan;
}

}  // namespace bsp
