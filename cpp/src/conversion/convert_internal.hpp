// Pieces of convert_csv shared between its source files (not a public header).
#pragma once
#include <array>
#include <cstdint>
#include <exception>
#include <string>
#include <utility>
#include <vector>

#include "bsp/clips/clips.hpp"
#include "bsp/conversion/convert.hpp"
#include "bsp/csv/csv.hpp"
#include "hdf5/h5.hpp"

namespace bsp::detail {

// `cells`: the pose columns' source when the table defers them (CsvReadOptions::deferred),
// else nullptr (the table's arrays).
void write_split(const h5::Group& g, const PoseTable& t, const DeferredCells* cells,
                 const Plan& plan, const std::vector<Clip>& clips, int L,
                 const ConvertOptions& opt, ConvertProgress* progress);
void write_clip_meta(const h5::Group& g, const PoseTable& t, const Plan& plan,
                     const std::vector<Clip>& clips, int L);
// Per recording: largest disagreement between the pose columns (mm) and between
// pose.camera and the projection of pose.world (px).
std::vector<VerifyRow> verify_recordings(const PoseTable& t, const Plan& plan, double fov,
                                         int threads);

// ---- Media (convert_media_*.cpp) ------------------------------------------------------

// One split's frame table: every frame its clips use, once, ordered by recording (plan
// order) and frame.idx, so each recording's frames form one contiguous block.
struct FrameTable {
  std::vector<std::uint32_t> recordings;  // plan recording of each block, in table order
  std::vector<std::size_t> begin;         // first table row of each block (+ the end)
  std::vector<std::size_t> rows;          // CSV row of each table frame
  std::vector<std::int64_t> clip_frames;  // clips.size() * L table rows
  std::size_t frames() const { return rows.size(); }
};
FrameTable plan_frame_table(const Plan& plan, const std::vector<Clip>& clips, int L);

// Full paths of a recording's MP4 and APNG (dataset root + CSV path).
struct MediaFiles {
  std::string video, segmentation;
};
// Resolves the media paths of every planned recording against `root`. Refuses (bsp::Error
// naming the CSV line and column) empty and absolute paths and paths with a `..` component
// before anything is opened, and paths that differ between rows of one recording.
std::vector<MediaFiles> media_files(const PoseTable& t, const Plan& plan, const std::string& root);

// A recording whose media cannot be used: the file, the reason, the original exception.
struct MediaFailure {
  std::uint32_t recording = 0;
  std::string path, reason;
  std::exception_ptr error;
};

// Opens the files of every recording in `tables` (in parallel) and checks that they exist,
// match the CSV's image size and hold every needed frame (APNG frames through
// video_to_apng_frames). Failures come back in recording order.
std::vector<MediaFailure> check_media(const PoseTable& t, const std::array<FrameTable, 3>& tables,
                                      const std::vector<MediaFiles>& files, int threads,
                                      ConvertProgress* progress);

// The frame table's datasets (under frames/), one row per table frame; the last two only
// with a crop context (MediaOptions::crop_context > 1).
enum FrameColumnId {
  kColRgb, kColMask, kColCropBox, kColJointVisible, kColMaskBbox, kColPixels, kColFrameIdx,
  kColContextRgb, kColContextBox
};
struct FrameColumn {
  std::string name;
  h5::Type type;
  std::vector<hsize_t> tail;  // shape after the frame axis
  std::size_t bytes;          // per frame
};
std::vector<FrameColumn> frame_columns(const MediaOptions& o);

// One recording's block of the frame table, column by column (frames x bytes).
struct MediaBlock {
  std::size_t frames = 0;
  std::vector<std::size_t> bytes;  // per frame, per column
  std::vector<std::vector<std::uint8_t>> cols;
  MediaFailure failure;  // failure.error set: decoding failed, the columns are incomplete
  template <class T>
  T* at(int col, std::size_t frame) {
    const auto c = static_cast<std::size_t>(col);
    return reinterpret_cast<T*>(cols[c].data() + frame * bytes[c]);
  }
};
// Decodes block `block` of `table`: the APNG frames first (statistics, crop boxes, masks),
// then only the crop (or context) region of each video frame. Errors are caught into
// block.failure. Counts finished frames in progress->done.
MediaBlock decode_block(const PoseTable& t, const FrameTable& table, std::size_t block,
                        const MediaFiles& files, const MediaOptions& o, ConvertProgress* progress);

// Decodes and crops the frame tables of the three splits and writes frames/* and
// clip_frames into each group (nullptr: decode only, to find failures). Without
// skip_bad_media the first failure is rethrown; with it, failures are returned and nothing
// more is written after the first (the caller converts again without those recordings).
// `occluded`: frame-table rows without a pedestrian pixel, per split (written blocks).
std::vector<MediaFailure> write_media(const std::array<const h5::Group*, 3>& groups,
                                      const PoseTable& t, const std::array<FrameTable, 3>& tables,
                                      const std::vector<MediaFiles>& files,
                                      const ConvertOptions& opt, ConvertProgress* progress,
                                      std::array<std::size_t, 3>& occluded);

// ---- Shards (shard.cpp) ----------------------------------------------------------------

// What shard `index` of `count` writes: per split, clips [first, second) and frame-table
// blocks [first, second).
struct ShardParts {
  std::array<std::pair<std::size_t, std::size_t>, 3> clips, blocks;
};
ShardParts shard_parts(const Plan& plan, const std::array<FrameTable, 3>& tables, int index,
                       int count);
// The blocks and the clips' clip_frames (still numbered in the whole table) of one shard.
FrameTable slice_table(const FrameTable& full, std::pair<std::size_t, std::size_t> blocks,
                       std::pair<std::size_t, std::size_t> clips, int L);

}  // namespace bsp::detail
