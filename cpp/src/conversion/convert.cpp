#include "bsp/conversion/convert.hpp"
#include "bsp/csv/columns.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <memory>
#include <set>
#include <stdexcept>
#include <tuple>

#include "bsp/geometry/camera.hpp"
#include "bsp/geometry/skeleton.hpp"
#include "convert_internal.hpp"

namespace bsp {
namespace {

using Clock = std::chrono::steady_clock;
double since(Clock::time_point t0) {
  return std::chrono::duration<double>(Clock::now() - t0).count();
}

std::vector<std::string> needed_columns(bool media) {
  std::vector<std::string> c = {
      "id", "world.map", "camera.idx", "camera.transform", "camera.width", "camera.height",
      "pedestrian.idx", "pedestrian.model", "pedestrian.age", "pedestrian.gender", "frame.idx",
      "camera.recording", "frame.pedestrian.transform", "frame.pedestrian.velocity",
      "frame.pedestrian.pose.world", "frame.pedestrian.pose.component",
      "frame.pedestrian.pose.relative", "frame.pedestrian.is_crossing",
      "frame.pedestrian.pose.camera"};
  if (media) c.push_back("camera.semantic_segmentation");
  return c;
}

using RecordingKey = std::tuple<std::int32_t, std::int64_t, std::int64_t>;

RowKeys keys_of(const PoseTable& t) {
  RowKeys k;
  k.rows = t.rows;
  k.id_code = t.id.codes.data();
  k.camera_idx = t.camera_idx.data();
  k.pedestrian_idx = t.pedestrian_idx.data();
  k.frame_idx = t.frame_idx.data();
  k.is_crossing = t.is_crossing.data();
  k.pose_camera = t.pose_camera.data();
  k.width = t.camera_width.data();
  k.height = t.camera_height.data();
  return k;
}

std::string label_rule(const ClipOptions& c) {
  if (c.benchmark) return "video";
  if (c.label_fraction > 0) return "any:" + std::to_string(c.label_fraction);
  return "last";
}

std::string deflate_name(int level) {
  return level > 0 ? "shuffle+deflate:" + std::to_string(level) : std::string("none");
}

void media_attrs(const h5::Group& g, const MediaOptions& m) {
  g.attr("media", std::int64_t{m.enabled});
  if (!m.enabled) return;
  g.attr("crop_size", std::int64_t{m.crop_size});
  g.attr("crop_box", std::string(crop_box_name(m.crop_box)));
  g.attr("crop_context", m.crop_context);
  g.attr("crop_scale", kCropScale);
  g.attr("crop_min_size", std::int64_t{kCropMinSize});
  g.attr("visibility_radius", std::int64_t{kVisibilityRadius});
  g.attr("pedestrian_tag", std::int64_t{kPedestrianTag});
  g.attr("media_compression", "frames/rgb " + deflate_name(m.rgb_level) + ", frames/mask " +
                                  deflate_name(m.mask_level));
  g.attr("skip_bad_media", std::int64_t{m.skip_bad_media});
}

void root_attrs(const h5::Group& g, const ConvertOptions& o, const ConvertReport& r) {
  const ClipOptions& c = o.clips;
  const int L = c.length, stride = c.stride ? c.stride : L;
  g.attr("schema_version", std::int64_t{1});
  g.attr("created_by", std::string("bsp_fast ") + BSP_VERSION);
  g.attr("clip_length", std::int64_t{L});
  g.attr("clip_stride", std::int64_t{stride});
  g.attr("eval_clip_stride", std::int64_t{c.eval_stride ? c.eval_stride : stride});
  g.attr("min_video_length", std::int64_t{c.min_video_length ? c.min_video_length : L});
  g.attr("label_rule", label_rule(c));
  g.attr("benchmark", std::int64_t{c.benchmark});
  g.attr("val_frac", c.val_frac);
  g.attr("test_frac", c.test_frac);
  g.attr("seed", static_cast<std::int64_t>(c.seed));
  g.attr("balance", std::int64_t{c.balance});
  g.attr("fov", o.fov);
  g.attr("compression", o.compress ? "shuffle+deflate:" + std::to_string(o.compression_level) : std::string("none"));
  g.attr("class_labels", std::vector<std::string>{"not-crossing", "crossing"});
  g.attr("joint_names", std::vector<std::string>(skeleton::kNames.begin(), skeleton::kNames.end()));
  g.attr("parents", std::vector<std::int64_t>(skeleton::kParents.begin(), skeleton::kParents.end()));
  g.attr("rotation_convention",
         std::string("CARLA/Unreal: R = Rz(yaw) Ry(-pitch) Rx(-roll), left-handed, Z up, "
                     "row-major 3x3 acting on column vectors"));
  g.attr("source_path", o.source_path);
  g.attr("source_crc32", static_cast<std::int64_t>(r.source_crc32));
  g.attr("source_bytes", static_cast<std::int64_t>(r.source_bytes));
  media_attrs(g, o.media);
  if (o.media.enabled)
    g.attr("media_recordings_left_out", static_cast<std::int64_t>(r.media.bad.size()));
  for (const auto& [k, v] : o.extra_attrs) g.attr(k, v);
  for (int s = 0; s < 3; ++s) {
    g.attr(std::string("class_counts_") + kSplitNames[s],
           std::vector<std::int64_t>{static_cast<std::int64_t>(r.class_counts[s][0]),
                                     static_cast<std::int64_t>(r.class_counts[s][1])});
  }
}

void fill_report(ConvertReport& r, const PoseTable& t, const Plan& plan) {
  r.rows = t.rows;
  r.recordings = plan.recordings.size();
  for (int s = 0; s < 3; ++s) {
    r.clips[s] = plan.splits[s].size();
    r.recordings_per_split[s] = plan.split_recordings[s].size();
    for (const Clip& c : plan.splits[s]) ++r.class_counts[s][c.label ? 1 : 0];
  }
  for (const auto& sk : plan.skipped) {
    const Recording& rec = plan.recordings[sk.recording];
    const std::size_t r0 = rec.rows.front();
    r.skipped.emplace_back(t.recording.values[static_cast<std::size_t>(t.recording.codes[r0])] +
                               " (" + std::to_string(rec.camera_idx) + "_" +
                               std::to_string(rec.pedestrian_idx) + ")",
                           sk.reason);
  }
  r.clips_rejected_out_of_image = plan.clips_rejected_out_of_image;
  r.clips_dropped_by_balance = plan.clips_dropped_by_balance;
}

// plan_clips over the rows of every recording not in `excluded`, with Recording::rows
// mapped back to rows of `t` (media left out with skip_bad_media: as if never recorded).
Plan plan_excluding(const PoseTable& t, const ClipOptions& o, const std::set<RecordingKey>& excluded) {
  if (excluded.empty()) return plan_clips(keys_of(t), o);
  std::vector<std::size_t> keep;
  for (std::size_t r = 0; r < t.rows; ++r)
    if (!excluded.count({t.id.codes[r], t.camera_idx[r], t.pedestrian_idx[r]})) keep.push_back(r);
  std::vector<std::int32_t> id;
  std::vector<std::int64_t> cam, ped, frame, width, height;
  std::vector<std::uint8_t> crossing;
  std::vector<float> uv;
  for (std::size_t r : keep) {
    id.push_back(t.id.codes[r]), cam.push_back(t.camera_idx[r]), ped.push_back(t.pedestrian_idx[r]);
    frame.push_back(t.frame_idx[r]), crossing.push_back(t.is_crossing[r]);
    width.push_back(t.camera_width[r]), height.push_back(t.camera_height[r]);
    uv.insert(uv.end(), &t.pose_camera[r * 52], &t.pose_camera[r * 52] + 52);
  }
  RowKeys k;
  k.rows = keep.size();
  k.id_code = id.data(), k.camera_idx = cam.data(), k.pedestrian_idx = ped.data();
  k.frame_idx = frame.data(), k.is_crossing = crossing.data(), k.pose_camera = uv.data();
  k.width = width.data(), k.height = height.data();
  Plan plan = plan_clips(k, o);
  for (Recording& rec : plan.recordings)
    for (std::size_t& r : rec.rows) r = keep[r];
  return plan;
}

std::string media_root(const std::string& csv_path) {
  const std::string dir = std::filesystem::path(csv_path).parent_path().string();
  return dir.empty() ? std::string(".") : dir;
}

void check_media_options(const MediaOptions& m) {
  if (!m.enabled) return;
  if (m.crop_size < 8 || m.crop_size > 1024)
    throw std::invalid_argument("crop size must lie in [8, 1024], got " + std::to_string(m.crop_size));
  if (m.rgb_level < 0 || m.rgb_level > 9 || m.mask_level < 0 || m.mask_level > 9)
    throw std::invalid_argument("deflate levels of the frame table must lie in [0, 9] (0 = none)");
  if (m.chunk_frames < 1) throw std::invalid_argument("chunk_frames must be positive");
  if (!(m.crop_context >= 1.0 && m.crop_context <= 4.0))
    throw std::invalid_argument("crop context must lie in [1, 4], got " + std::to_string(m.crop_context));
}

// What the media stage of one pass works on.
struct MediaPlan {
  std::vector<detail::MediaFiles> files;
  std::array<detail::FrameTable, 3> tables;
};

// Adds the recordings of `failures` to `excluded` and their files to the report's list.
void exclude(const Plan& plan, const std::vector<detail::MediaFailure>& failures,
             std::set<RecordingKey>& excluded, std::vector<BadMedia>& bad) {
  for (const auto& f : failures) {
    const Recording& rec = plan.recordings[f.recording];
    excluded.insert({rec.id_code, rec.camera_idx, rec.pedestrian_idx});
    bad.push_back({f.path, f.reason});
  }
}

// Writes the whole file. Returns the recordings whose media failed while decoding (only
// with skip_bad_media); the file is then incomplete and the caller converts again.
// `clips`: the clips of each split to write (a shard's part; all of them otherwise);
// `keep_failures`: media failures come back even without skip_bad_media (shards).
using SplitClips = std::array<const std::vector<Clip>*, 3>;

// 1 for each table row that one of the clips uses.
std::vector<std::uint8_t> used_rows(const PoseTable& t, const Plan& plan, const SplitClips& clips,
                                    int L) {
  std::vector<std::uint8_t> used(t.rows, 0);
  for (const auto* split : clips)
    for (const Clip& c : *split)
      for (std::size_t k = 0; k < static_cast<std::size_t>(L); ++k)
        used[plan.recordings[c.recording].rows[c.first + k]] = 1;
  return used;
}

// `cells`: the deferred pose columns (nullptr: the table holds them), parsed while the
// clips are written; the rows no clip uses are checked afterwards, so a malformed cell
// anywhere still fails the conversion.
std::vector<detail::MediaFailure> write_output(const std::string& out_path, const PoseTable& table,
                                               const DeferredCells* cells,
                                               const Plan& plan, const SplitClips& clips,
                                               const MediaPlan* media, const ConvertOptions& opt,
                                               ConvertReport& report, ConvertProgress* progress,
                                               bool keep_failures = false) {
  auto t0 = Clock::now();
  if (progress) {
    progress->done = 0;
    progress->total = clips[0]->size() + clips[1]->size() + clips[2]->size();
    progress->stage = ConvertStage::write;
  }
  h5::File file = h5::File::create(out_path);
  const h5::Group root = file.root();
  root_attrs(root, opt, report);
  std::vector<h5::Group> groups;
  for (int s = 0; s < 3; ++s) {
    groups.push_back(root.create_group(kSplitNames[s]));
    const h5::Group& g = groups.back();
    g.attr("class_counts", std::vector<std::int64_t>{static_cast<std::int64_t>(report.class_counts[s][0]),
                                                     static_cast<std::int64_t>(report.class_counts[s][1])});
    g.attr("recordings", static_cast<std::int64_t>(report.recordings_per_split[s]));
    detail::write_split(g, table, cells, plan, *clips[static_cast<std::size_t>(s)],
                        opt.clips.length, opt, progress);
  }
  if (cells) cells->check_rows(used_rows(table, plan, clips, opt.clips.length), opt.threads);
  report.seconds["write"] = since(t0);
  std::vector<detail::MediaFailure> failed;
  if (media) {
    t0 = Clock::now();
    if (progress) {
      progress->done = 0;
      progress->total = media->tables[0].frames() + media->tables[1].frames() + media->tables[2].frames();
      progress->stage = ConvertStage::media;
    }
    ConvertOptions mo = opt;
    mo.media.skip_bad_media = opt.media.skip_bad_media || keep_failures;
    failed = detail::write_media(std::array<const h5::Group*, 3>{&groups[0], &groups[1], &groups[2]},
                                 table, media->tables, media->files, mo, progress,
                                 report.media.fully_occluded);
    for (std::size_t s = 0; s < 3; ++s)
      groups[s].attr("fully_occluded_frames", static_cast<std::int64_t>(report.media.fully_occluded[s]));
    report.seconds["media"] = since(t0);
  }
  file.close();
  return failed;
}

// One planning pass, shared by convert_csv and convert_shard: the clips without the
// `excluded` recordings (their counts into `report`) and, with media, the files of every
// planned recording (unsafe paths refused first) and the frame table of each split.
struct Pass {
  Plan plan;
  MediaPlan media;
};
Pass plan_pass(const PoseTable& table, const std::set<RecordingKey>& excluded,
               const std::string& csv_path, const ConvertOptions& opt, ConvertReport& report) {
  const auto t0 = Clock::now();
  Pass pass;
  pass.plan = plan_excluding(table, opt.clips, excluded);
  fill_report(report, table, pass.plan);
  if (opt.media.enabled) {
    pass.media.files = detail::media_files(table, pass.plan, media_root(csv_path));
    for (int s = 0; s < 3; ++s)
      pass.media.tables[s] = detail::plan_frame_table(pass.plan, pass.plan.splits[s], opt.clips.length);
  }
  report.seconds["plan"] = since(t0);
  return pass;
}

void verify(const PoseTable& table, const Plan& plan, const ConvertOptions& opt,
            ConvertReport& report, ConvertProgress* progress) {
  if (progress) progress->stage = ConvertStage::verify;
  const auto t0 = Clock::now();
  report.verify = detail::verify_recordings(table, plan, opt.fov, opt.threads);
  for (const VerifyRow& v : report.verify)
    if (!(v.component_mm <= opt.verify_tol_mm && v.world_mm <= opt.verify_world_tol_mm &&
          v.camera_px <= opt.verify_tol_px))
      report.verify_failed.push_back(v.recording);
  report.seconds["verify"] = since(t0);
}

LeftOutRecording left_out(const PoseTable& t, const Plan& plan, const detail::MediaFailure& f) {
  const Recording& rec = plan.recordings[f.recording];
  return {t.id.values[static_cast<std::size_t>(rec.id_code)], rec.camera_idx, rec.pedestrian_idx,
          f.path, f.reason};
}

// Shard opt.shard.index of opt.shard.count (ShardOptions): the plan of the whole dataset,
// this shard's part of it written to out_path; media failures returned, not thrown (the
// file is then incomplete and the caller discards it).
ConvertReport convert_shard(const std::string& csv_path, const std::string& out_path,
                            const PoseTable& table, ConvertReport report,
                            const std::set<RecordingKey>& excluded, const ConvertOptions& opt,
                            ConvertProgress* progress) {
  const Pass pass = plan_pass(table, excluded, csv_path, opt, report);
  const Plan& plan = pass.plan;
  const int L = opt.clips.length;
  const detail::ShardParts parts =
      detail::shard_parts(plan, pass.media.tables, opt.shard.index, opt.shard.count);
  std::array<std::vector<Clip>, 3> clips;
  MediaPlan media;  // this shard's blocks of the frame tables
  media.files = pass.media.files;
  for (std::size_t s = 0; s < 3; ++s) {
    const auto [c0, c1] = parts.clips[s];
    clips[s].assign(plan.splits[s].begin() + static_cast<std::ptrdiff_t>(c0),
                    plan.splits[s].begin() + static_cast<std::ptrdiff_t>(c1));
    if (opt.media.enabled)
      media.tables[s] = detail::slice_table(pass.media.tables[s], parts.blocks[s], parts.clips[s], L);
  }
  if (opt.media.enabled) {
    const auto t0 = Clock::now();
    auto failed = detail::check_media(table, media.tables, media.files, opt.threads, progress);
    report.media.check_seconds = since(t0);
    for (const auto& f : failed)
      report.shard_failures.push_back({FailurePhase::open, f.recording, left_out(table, plan, f),
                                       error_kind(f.error)});
    if (!failed.empty()) return report;
  }
  check_cancel(progress);
  if (opt.verify && opt.shard.index == 0) verify(table, plan, opt, report, progress);
  const SplitClips mine = {&clips[0], &clips[1], &clips[2]};
  auto failed = write_output(out_path, table, nullptr, plan, mine,
                             opt.media.enabled ? &media : nullptr, opt, report, progress,
                             /*keep_failures=*/true);
  for (const auto& f : failed) {
    std::uint64_t order = 0;  // split << 32 | block in the whole split's table
    for (std::size_t s = 0; s < 3; ++s) {
      const auto& recs = media.tables[s].recordings;
      const auto it = std::find(recs.begin(), recs.end(), f.recording);
      if (it != recs.end())
        order = (std::uint64_t{s} << 32) |
                (parts.blocks[s].first + static_cast<std::uint64_t>(it - recs.begin()));
    }
    report.shard_failures.push_back({FailurePhase::decode, order, left_out(table, plan, f),
                                     error_kind(f.error)});
  }
  for (std::size_t s = 0; s < 3; ++s) report.media.frames[s] = media.tables[s].frames();
  report.media.seconds = report.media.check_seconds + (opt.media.enabled ? report.seconds["media"] : 0.0);
  report.media.passes = 1;
  if (progress) progress->stage = ConvertStage::done;
  return report;
}

RecordingKey key_of(const PoseTable& t, const LeftOutRecording& r) {
  const auto& ids = t.id.values;
  const auto it = std::find(ids.begin(), ids.end(), r.id);
  if (it == ids.end()) throw std::invalid_argument("recording to leave out not in data.csv: " + r.id);
  return {static_cast<std::int32_t>(it - ids.begin()), r.camera_idx, r.pedestrian_idx};
}

// The planning and writing passes of convert_csv: again without the recordings whose
// media failed (skip_bad_media) until a pass writes the whole file.
ConvertReport convert_passes(const std::string& csv_path, const std::string& out_path,
                             const PoseTable& table, const DeferredCells* cells,
                             const ConvertReport& base, std::set<RecordingKey> excluded,
                             std::vector<BadMedia> bad, const ConvertOptions& opt,
                             ConvertProgress* progress) {
  double check_seconds = 0;
  for (int writes = 1;;) {
    check_cancel(progress);
    ConvertReport report = base;
    const Pass pass = plan_pass(table, excluded, csv_path, opt, report);
    const Plan& plan = pass.plan;
    const MediaPlan& media = pass.media;
    if (opt.media.enabled) {
      const auto t0 = Clock::now();
      auto failed = detail::check_media(table, media.tables, media.files, opt.threads, progress);
      check_seconds += since(t0);
      if (!failed.empty() && !opt.media.skip_bad_media) std::rethrow_exception(failed.front().error);
      if (!failed.empty()) {
        exclude(plan, failed, excluded, bad);
        continue;
      }
    }
    check_cancel(progress);
    if (opt.verify) verify(table, plan, opt, report, progress);
    check_cancel(progress);
    report.media.bad = bad;
    const SplitClips all = {&plan.splits[0], &plan.splits[1], &plan.splits[2]};
    auto failed = write_output(out_path, table, cells, plan, all,
                               opt.media.enabled ? &media : nullptr, opt, report, progress);
    if (!failed.empty()) {
      exclude(plan, failed, excluded, bad);
      ++writes;
      continue;
    }
    for (int s = 0; s < 3; ++s) report.media.frames[s] = media.tables[s].frames();
    report.media.check_seconds = check_seconds;
    report.media.seconds = check_seconds + (opt.media.enabled ? report.seconds["media"] : 0.0);
    report.media.passes = writes;
    if (progress) progress->stage = ConvertStage::done;
    return report;
  }
}

// The three 26-joint pose columns, 85 % of data.csv: without media, --verify or shards
// (which read them for every row), bsp-convert parses them only while it writes each clip
// (DeferredCells), so the table never holds them: half a gigabyte less memory for the
// published size, and the parsing overlaps the writing.
const std::vector<std::string> kDeferredPoses = {
    "frame.pedestrian.pose.world", "frame.pedestrian.pose.component",
    "frame.pedestrian.pose.relative"};
bool defer_poses(const ConvertOptions& o) {
  return !o.media.enabled && !o.verify && o.shard.count == 0;
}

// Runs fn() (planning and writing); with deferred cells, a malformed pose cell anywhere is
// reported as read_pose_csv reports it and before any other error, as when the cells were
// parsed while reading: they are all checked before an error other than a cancel leaves.
template <class Fn>
ConvertReport deferred_errors_first(const DeferredCells* cells, const ConvertOptions& opt,
                                    const PoseTable& t, const ConvertProgress* progress, Fn&& fn) {
  if (!cells) return fn();
  try {
    return fn();
  } catch (const DeferredCellError&) {
    cells->throw_parse_error();
  } catch (...) {
    if (!(progress && progress->cancel.load(std::memory_order_relaxed))) {
      try {
        cells->check_rows(std::vector<std::uint8_t>(t.rows, 0), opt.threads);
      } catch (const DeferredCellError&) {
        cells->throw_parse_error();
      }
    }
    throw;
  }
}

}  // namespace

void check_cancel(const ConvertProgress* p) {
  if (p && p->cancel.load(std::memory_order_relaxed)) throw Error("conversion cancelled");
}

ConvertReport convert_csv(const std::string& csv_path, const std::string& out_path,
                          const ConvertOptions& opt, ConvertProgress* progress) {
  check_media_options(opt.media);
  ConvertReport base;
  auto t0 = Clock::now();
  CsvReadOptions ro;
  ro.columns = needed_columns(opt.media.enabled);
  ro.threads = opt.threads;
  if (defer_poses(opt)) ro.deferred = kDeferredPoses;
  if (progress) ro.rows_total = &progress->total, ro.rows_done = &progress->done;  // read: rows
  const PoseTable table = read_pose_csv(csv_path, ro);
  const std::unique_ptr<DeferredCells> cells =
      defer_poses(opt) ? std::make_unique<DeferredCells>(table, ro) : nullptr;
  return deferred_errors_first(cells.get(), opt, table, progress, [&] {
    check_utf8(table);  // ids and paths reach Python and HDF5 as text
    base.source_crc32 = table.file_crc32;  // computed while the reader scanned the file
    base.source_bytes = table.file_bytes;
    base.seconds["read"] = since(t0);
    if (progress) progress->done = table.rows, progress->stage = ConvertStage::plan;
    std::set<RecordingKey> excluded;
    std::vector<BadMedia> bad;
    for (const LeftOutRecording& r : opt.shard.exclude) {
      excluded.insert(key_of(table, r));
      bad.push_back({r.path, r.reason});
    }
    if (opt.shard.count > 0) {
      base.media.bad = bad;
      return convert_shard(csv_path, out_path, table, base, excluded, opt, progress);
    }
    return convert_passes(csv_path, out_path, table, cells.get(), base, excluded, bad, opt,
                          progress);
  });
}

}  // namespace bsp
