// Media planning: the per-split frame tables, the media paths (untrusted CSV input: checked
// before anything is opened) and the check that opens every file before decoding starts.
#include <sys/stat.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <map>
#include <thread>

#include "bsp/common/parallel.hpp"
#include "bsp/media/apng.hpp"
#include "bsp/media/video.hpp"
#include "convert_internal.hpp"

namespace bsp::detail {
namespace {

const std::string& str_at(const StringColumn& c, std::size_t row) {
  return c.values[static_cast<std::size_t>(c.codes[row])];
}

// A CSV media path made absolute under `root`, or a bsp::Error saying why it is refused.
std::string resolve_path(const PoseTable& t, std::size_t row, const char* column,
                         const std::string& rel, const std::string& root) {
  const std::string where = t.path + ":" + std::to_string(t.line[row]) + ": column " + column + ": ";
  if (rel.empty()) throw Error(where + "empty media path");
  if (rel.find('\0') != std::string::npos) throw Error(where + "media path holds a NUL byte");
  if (rel.front() == '/')
    throw Error(where + "media path \"" + rel +
                "\" is absolute; paths must be relative to the dataset root (refused, not opened)");
  std::size_t start = 0;
  for (;;) {
    const std::size_t end = std::min(rel.find('/', start), rel.size());
    if (rel.compare(start, end - start, "..") == 0)
      throw Error(where + "media path \"" + rel +
                  "\" leaves the dataset root through '..' (refused, not opened)");
    if (end == rel.size()) break;
    start = end + 1;
  }
  // Symlinks may not lead out either: the real path must stay under the root's real path.
  const std::string path = root + "/" + rel;
  std::unique_ptr<char, void (*)(void*)> real(::realpath(path.c_str(), nullptr), &std::free);
  std::unique_ptr<char, void (*)(void*)> real_root(::realpath(root.c_str(), nullptr), &std::free);
  if (real && real_root) {
    const std::string r(real.get()), rr(real_root.get());
    if (r.compare(0, rr.size(), rr) != 0 || (r.size() > rr.size() && r[rr.size()] != '/' &&
                                             rr != "/"))
      throw Error(where + "media path \"" + rel + "\" resolves to " + r +
                  ", outside the dataset root " + rr + " (a symlink leading out: refused, not opened)");
  }
  return path;
}

// Every row of a recording must name the same file in `col`.
void check_same_path(const PoseTable& t, const Recording& rec, const StringColumn& col,
                     const char* column) {
  const std::int32_t code = col.codes[rec.rows.front()];
  for (std::size_t r : rec.rows)
    if (col.codes[r] != code)
      throw Error(t.path + ":" + std::to_string(t.line[r]) + ": column " + column + ": \"" +
                  str_at(col, r) + "\" differs from \"" + str_at(col, rec.rows.front()) +
                  "\" (line " + std::to_string(t.line[rec.rows.front()]) +
                  ") of the same recording");
}

std::string missing_reason(const std::string& path) {
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0) return path + ": cannot open: " + std::strerror(errno);
  if (!S_ISREG(st.st_mode)) return path + ": not a regular file";
  return {};
}

// Opens both files of one recording and checks them against the frames `rows` needs.
void check_recording(const PoseTable& t, const std::size_t* rows, std::size_t n,
                     const MediaFiles& f, std::string& failed_path) {
  const std::int64_t W = t.camera_width[rows[0]], H = t.camera_height[rows[0]];
  const std::int64_t last = t.frame_idx[rows[n - 1]];
  failed_path = f.video;
  if (std::string why = missing_reason(f.video); !why.empty()) throw Error(why);
  VideoReader video(f.video, 1);
  if (video.width() != W || video.height() != H)
    throw VideoDecodeError(f.video + ": picture is " + std::to_string(video.width()) + "x" +
                           std::to_string(video.height()) + " but data.csv says " +
                           std::to_string(W) + "x" + std::to_string(H));
  if (last >= video.frame_count())
    throw VideoDecodeError(f.video + ": frame " + std::to_string(last) + " needed but the file has " +
                           std::to_string(video.frame_count()) + " frames");
  failed_path = f.segmentation;
  if (std::string why = missing_reason(f.segmentation); !why.empty()) throw Error(why);
  ApngReader seg(f.segmentation);
  if (!seg.indexed() || seg.width() != W || seg.height() != H)
    throw ApngError(f.segmentation + ": expected an 8-bit palette-indexed " + std::to_string(W) + "x" +
                    std::to_string(H) + " APNG of class tags");
  const auto map = seg.video_to_apng_frames(last + 1, video.fps());
  for (std::size_t i = 0; i < n; ++i) {
    const std::int64_t k = t.frame_idx[rows[i]];
    if (map[static_cast<std::size_t>(k)] < 0 && !seg.damage().empty())
      throw ApngError(f.segmentation + ": video frame " + std::to_string(k) +
                      " cannot be decoded: the file is damaged at " + seg.damage());
    if (map[static_cast<std::size_t>(k)] < 0)
      throw ApngError(f.segmentation + ": video frame " + std::to_string(k) +
                      " is shown after the animation's end (" +
                      std::to_string(seg.frame_count()) + " frames)");
  }
}

}  // namespace

FrameTable plan_frame_table(const Plan& plan, const std::vector<Clip>& clips, int L) {
  // Table position of every used (recording, row position); -1 = unused.
  std::map<std::uint32_t, std::vector<std::int64_t>> used;
  for (const Clip& c : clips) {
    auto& pos = used[c.recording];
    if (pos.empty()) pos.assign(plan.recordings[c.recording].rows.size(), -1);
    for (int f = 0; f < L; ++f) pos[c.first + static_cast<std::size_t>(f)] = 0;
  }
  FrameTable ft;
  for (auto& [rec, pos] : used) {  // std::map: ascending recording index
    ft.recordings.push_back(rec);
    ft.begin.push_back(ft.rows.size());
    for (std::size_t p = 0; p < pos.size(); ++p) {
      if (pos[p] < 0) continue;
      pos[p] = static_cast<std::int64_t>(ft.rows.size());
      ft.rows.push_back(plan.recordings[rec].rows[p]);
    }
  }
  ft.begin.push_back(ft.rows.size());
  ft.clip_frames.reserve(clips.size() * static_cast<std::size_t>(L));
  for (const Clip& c : clips)
    for (int f = 0; f < L; ++f) ft.clip_frames.push_back(used[c.recording][c.first + static_cast<std::size_t>(f)]);
  return ft;
}

std::vector<MediaFiles> media_files(const PoseTable& t, const Plan& plan, const std::string& root) {
  std::vector<MediaFiles> files(plan.recordings.size());
  for (std::size_t i = 0; i < files.size(); ++i) {
    const Recording& rec = plan.recordings[i];
    const std::size_t r0 = rec.rows.front();
    files[i].video = resolve_path(t, r0, "camera.recording", str_at(t.recording, r0), root);
    files[i].segmentation =
        resolve_path(t, r0, "camera.semantic_segmentation", str_at(t.segmentation, r0), root);
    check_same_path(t, rec, t.recording, "camera.recording");
    check_same_path(t, rec, t.segmentation, "camera.semantic_segmentation");
  }
  return files;
}

std::vector<MediaFailure> check_media(const PoseTable& t, const std::array<FrameTable, 3>& tables,
                                      const std::vector<MediaFiles>& files, int threads,
                                      ConvertProgress* progress) {
  struct Item {
    const FrameTable* table;
    std::size_t block;
  };
  std::vector<Item> items;
  for (const FrameTable& ft : tables)
    for (std::size_t b = 0; b < ft.recordings.size(); ++b) items.push_back({&ft, b});
  std::sort(items.begin(), items.end(), [](const Item& a, const Item& b) {
    return a.table->recordings[a.block] < b.table->recordings[b.block];
  });
  if (progress) progress->done = 0, progress->total = items.size(),
                progress->stage = ConvertStage::check_media;
  std::vector<MediaFailure> result(items.size());
  std::atomic<std::size_t> next{0};
  auto work = [&] {
    for (std::size_t i; (i = next++) < items.size();) {
      if (progress && progress->cancel) break;
      const FrameTable& ft = *items[i].table;
      const std::size_t b = items[i].block, rec = ft.recordings[b];
      result[i].recording = static_cast<std::uint32_t>(rec);
      try {
        check_recording(t, &ft.rows[ft.begin[b]], ft.begin[b + 1] - ft.begin[b], files[rec],
                        result[i].path);
      } catch (const std::exception& e) {
        result[i].reason = e.what();
        result[i].error = std::current_exception();
      } catch (...) {
        result[i].reason = "unknown error";
        result[i].error = std::current_exception();
      }
      if (progress) ++progress->done;
    }
  };
  const int n = std::min<int>(threads > 0 ? threads : num_threads(), static_cast<int>(items.size()));
  std::vector<std::thread> pool;
  for (int i = 1; i < n; ++i) pool.emplace_back(work);
  work();
  for (auto& th : pool) th.join();
  check_cancel(progress);
  std::vector<MediaFailure> failed;
  for (auto& r : result)
    if (r.error) failed.push_back(std::move(r));
  return failed;
}

}  // namespace bsp::detail
