#include "bsp/convert.hpp"

#include <fcntl.h>
#include <libdeflate.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <cstring>

#include "bsp/camera.hpp"
#include "bsp/convert_internal.hpp"
#include "bsp/skeleton.hpp"

namespace bsp {
namespace {

using Clock = std::chrono::steady_clock;
double since(Clock::time_point t0) {
  return std::chrono::duration<double>(Clock::now() - t0).count();
}

// CRC-32 of the whole file through mmap (libdeflate's CRC runs at several GB/s).
std::uint32_t file_crc32(const std::string& path, std::uint64_t& bytes) {
  const int fd = ::open(path.c_str(), O_RDONLY);
  if (fd < 0) throw Error("cannot open " + path + ": " + std::strerror(errno));
  struct stat st {};
  ::fstat(fd, &st);
  bytes = static_cast<std::uint64_t>(st.st_size);
  std::uint32_t crc = 0;
  if (bytes) {
    void* p = ::mmap(nullptr, bytes, PROT_READ, MAP_PRIVATE, fd, 0);
    if (p == MAP_FAILED) {
      ::close(fd);
      throw Error("cannot mmap " + path + ": " + std::strerror(errno));
    }
    crc = libdeflate_crc32(0, p, bytes);
    ::munmap(p, bytes);
  }
  ::close(fd);
  return crc;
}

const std::vector<std::string>& needed_columns() {
  static const std::vector<std::string> c = {
      "id", "world.map", "camera.idx", "camera.transform", "camera.width", "camera.height",
      "pedestrian.idx", "pedestrian.model", "pedestrian.age", "pedestrian.gender", "frame.idx",
      "camera.recording", "frame.pedestrian.transform", "frame.pedestrian.velocity",
      "frame.pedestrian.pose.world", "frame.pedestrian.pose.component",
      "frame.pedestrian.pose.relative", "frame.pedestrian.is_crossing",
      "frame.pedestrian.pose.camera"};
  return c;
}

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

}  // namespace

ConvertReport convert_csv(const std::string& csv_path, const std::string& out_path,
                          const ConvertOptions& opt, ConvertProgress* progress) {
  ConvertReport report;
  auto t0 = Clock::now();
  report.source_crc32 = file_crc32(csv_path, report.source_bytes);
  if (progress) progress->total = report.source_bytes;
  CsvReadOptions ro;
  ro.columns = needed_columns();
  ro.threads = opt.threads;
  const PoseTable table = read_pose_csv(csv_path, ro);
  report.seconds["read"] = since(t0);
  if (progress) progress->done = report.source_bytes, progress->stage = 1;

  t0 = Clock::now();
  const Plan plan = plan_clips(keys_of(table), opt.clips);
  fill_report(report, table, plan);
  report.seconds["plan"] = since(t0);

  if (opt.verify) {
    if (progress) progress->stage = 2;
    t0 = Clock::now();
    report.verify = detail::verify_recordings(table, plan, opt.fov, opt.threads);
    for (const VerifyRow& v : report.verify)
      if (!(v.component_mm <= opt.verify_tol_mm && v.world_mm <= opt.verify_world_tol_mm &&
            v.camera_px <= opt.verify_tol_px))
        report.verify_failed.push_back(v.recording);
    report.seconds["verify"] = since(t0);
  }

  t0 = Clock::now();
  if (progress) {
    progress->done = 0;
    progress->total = report.clips[0] + report.clips[1] + report.clips[2];
    progress->stage = 3;
  }
  h5::File file = h5::File::create(out_path);
  const h5::Group root = file.root();
  root_attrs(root, opt, report);
  for (int s = 0; s < 3; ++s) {
    const h5::Group g = root.create_group(kSplitNames[s]);
    g.attr("class_counts", std::vector<std::int64_t>{static_cast<std::int64_t>(report.class_counts[s][0]),
                                                     static_cast<std::int64_t>(report.class_counts[s][1])});
    g.attr("recordings", static_cast<std::int64_t>(report.recordings_per_split[s]));
    detail::write_split(g, table, plan, plan.splits[s], opt.clips.length, opt, progress);
  }
  file.close();
  report.seconds["write"] = since(t0);
  if (progress) progress->stage = 4;
  return report;
}

}  // namespace bsp
