// Cutting one conversion into shards (docs/distributed.md): which clips and which
// frame-table blocks shard k of K writes.
#include <algorithm>
#include <stdexcept>

#include "bsp/common/errors.hpp"
#include "convert_internal.hpp"

namespace bsp::detail {

ShardParts shard_parts(const Plan& plan, const std::array<FrameTable, 3>& tables, int index,
                       int count) {
  if (count < 1 || index < 0 || index >= count)
    throw std::invalid_argument("shard index must lie in [0, " + std::to_string(count) +
                                "), got " + std::to_string(index));
  const auto K = static_cast<std::size_t>(count), k = static_cast<std::size_t>(index);
  ShardParts parts;
  for (int s = 0; s < 3; ++s) {
    const std::size_t n = plan.splits[static_cast<std::size_t>(s)].size();
    parts.clips[static_cast<std::size_t>(s)] = {n * k / K, n * (k + 1) / K};
  }
  // Blocks of all splits in table order (split 0 first), cut into K contiguous runs of
  // about equal frame counts: each split's share of a run is again one contiguous run.
  std::vector<std::size_t> cum = {0};  // frames before each global block
  for (const FrameTable& ft : tables)
    for (std::size_t b = 0; b + 1 < ft.begin.size(); ++b)
      cum.push_back(cum.back() + (ft.begin[b + 1] - ft.begin[b]));
  const std::size_t G = cum.size() - 1, F = cum.back();
  auto cut = [&](std::size_t j) -> std::size_t {  // first global block of shard j
    if (j == 0) return 0;
    if (j >= K) return G;
    std::size_t g = 0;
    while (g < G && cum[g] * K < j * F) ++g;
    return g;
  };
  const std::size_t g0 = cut(k), g1 = cut(k + 1);
  std::size_t first = 0;  // global index of the split's first block
  for (int s = 0; s < 3; ++s) {
    const FrameTable& ft = tables[static_cast<std::size_t>(s)];
    const std::size_t nb = ft.recordings.size();
    const std::size_t b0 = std::clamp(g0, first, first + nb) - first;
    const std::size_t b1 = std::clamp(g1, first, first + nb) - first;
    parts.blocks[static_cast<std::size_t>(s)] = {b0, b1};
    first += nb;
  }
  return parts;
}

FrameTable slice_table(const FrameTable& full, std::pair<std::size_t, std::size_t> blocks,
                       std::pair<std::size_t, std::size_t> clips, int L) {
  FrameTable t;
  const auto [b0, b1] = blocks;
  if (!full.begin.empty()) {
    const std::size_t r0 = full.begin[b0], r1 = full.begin[b1];
    t.recordings.assign(full.recordings.begin() + static_cast<std::ptrdiff_t>(b0),
                        full.recordings.begin() + static_cast<std::ptrdiff_t>(b1));
    for (std::size_t b = b0; b <= b1; ++b) t.begin.push_back(full.begin[b] - r0);
    t.rows.assign(full.rows.begin() + static_cast<std::ptrdiff_t>(r0),
                  full.rows.begin() + static_cast<std::ptrdiff_t>(r1));
  } else {
    t.begin.push_back(0);
  }
  const auto per = static_cast<std::size_t>(L);
  t.clip_frames.assign(full.clip_frames.begin() + static_cast<std::ptrdiff_t>(clips.first * per),
                       full.clip_frames.begin() + static_cast<std::ptrdiff_t>(clips.second * per));
  return t;
}

}  // namespace bsp::detail
