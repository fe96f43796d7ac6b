// bsp-convert: data.csv -> train/val/test clips in one HDF5 file (docs/dataset-format.md,
// "5. Geometry conventions" and "7. From rows to clips and splits").
#pragma once
#include <array>
#include <atomic>
#include <cstdint>
#include <map>
#include <string>
#include <vector>

#include "bsp/clips/clips.hpp"
#include "bsp/common/errors.hpp"

namespace bsp {

// What the crop box is made from (docs/hdf5-schema.md, "Crop box"): the segmentation
// mask's box only (what a person detector could see; a frame without a pedestrian pixel
// gets no crop), the union of the mask box and the ground-truth joint box (the first
// versions' crops: partly cut from the answer), or the joint box only.
enum class CropBoxPolicy : int { mask = 0, mask_joints = 1, joints = 2 };
// "mask", "mask+joints", "joints" (the CLI's and the HDF5 attribute's spelling).
const char* crop_box_name(CropBoxPolicy p);
// The policy of a name above; std::invalid_argument listing the names otherwise.
CropBoxPolicy crop_box_policy(const std::string& name);

// Media of every clip frame (on by default): pedestrian crops and masks in a per-split
// frame table (docs/hdf5-schema.md, "Frame table").
struct MediaOptions {
  bool enabled = true;
  int crop_size = 128;          // S: crops are S x S
  CropBoxPolicy crop_box = CropBoxPolicy::mask;
  // > 1: also store frames/context_rgb, the crop box widened by this factor about its
  // centre (side ceil(context * side)) at ceil(context * S) pixels, for box noise
  // (bsp_fast.data); 1 = none.
  double crop_context = 1.0;
  bool skip_bad_media = false;  // leave out recordings whose media is missing or broken
  // Measured in benchmarks/bench_convert_media.py (docs/hdf5-schema.md): masks shrink ~20x
  // with deflate 1 and still read at ~30k frames/s; RGB crops only ~2.5x, and deflated
  // RGB reads 15-30x slower, so it is opt-in (ConvertOptions::compress).
  int rgb_level = 0;            // deflate level of frames/rgb (0 = none); chunks of 1 frame
  int mask_level = 1;           // deflate level of frames/mask (0 = none)
  int chunk_frames = 16;        // frames per chunk of frames/mask and uncompressed frames/rgb
};

// A recording left out before planning (a media failure found by an earlier pass).
struct LeftOutRecording {
  std::string id;  // the CSV's id column
  std::int64_t camera_idx = 0, pedestrian_idx = 0;
  std::string path, reason;  // the bad file, as reported (BadMedia)
};

// One shard of a distributed conversion (docs/distributed.md). Every shard plans the whole
// dataset exactly as convert_csv does, then writes only its part: clips [N*k/K, N*(k+1)/K)
// of each split and the frame-table blocks (whole recordings) of its contiguous range of
// the table, so concatenating the shards along the first axis gives the one-file output.
// Media failures are not thrown but returned in ConvertReport::shard_failures.
struct ShardOptions {
  int count = 0;  // K; 0 = not sharded
  int index = 0;  // k in [0, K)
  std::vector<LeftOutRecording> exclude;  // planned without these (also when not sharded)
};

struct ConvertOptions {
  ClipOptions clips;
  ShardOptions shard;
  MediaOptions media;
  double fov = 90.0;         // horizontal FOV of the camera (not stored in the CSV)
  int threads = 0;           // 0 = all cores
  bool verify = false;       // cross-check the pose columns and the projection
  double verify_tol_mm = 1.0, verify_world_tol_mm = 20.0, verify_tol_px = 1.0;
  bool compress = false;     // byte-shuffle + deflate for the large target arrays
  int compression_level = 1;
  int chunk_clips = 64;      // clips per HDF5 chunk
  std::string source_path;   // stored as an attribute (the dataset directory)
  std::map<std::string, std::string> extra_attrs;  // e.g. the Python-side settings JSON
};

// What a conversion is doing (registered with pybind11 as _core.ConvertStage). In time:
// read, plan, check_media (with media), verify (with verify), write, media (with media),
// done. ConvertProgress's done/total count rows in `read`, media files in `check_media`,
// frames in `media`, clips otherwise.
enum class ConvertStage : int {
  read = 0, plan = 1, verify = 2, write = 3, done = 4, check_media = 5, media = 6
};

// Polled by the Python side from another thread (no callbacks into Python).
struct ConvertProgress {
  std::atomic<ConvertStage> stage{ConvertStage::read};
  std::atomic<std::uint64_t> done{0}, total{0};
  // Set from another thread to stop the conversion: every stage checks it between units of
  // work (rows of clips, media files, recordings), joins its worker threads and throws
  // bsp::Error("conversion cancelled"), leaving nothing running.
  std::atomic<bool> cancel{false};
};

// Throws bsp::Error("conversion cancelled") when `p` asks to stop.
void check_cancel(const ConvertProgress* p);

struct VerifyRow {
  std::string recording;  // video path without extension + "/<camera>_<pedestrian>"
  double component_mm = 0, world_mm = 0, camera_px = 0;
};

struct BadMedia {
  std::string path;    // the media file (dataset root + CSV path)
  std::string reason;  // the reader's message
};

struct MediaReport {
  std::array<std::size_t, 3> frames{};  // frame-table rows per split
  double seconds = 0;                   // checking, decoding, cropping and writing
  double check_seconds = 0;             // opening every file before decoding
  std::vector<BadMedia> bad;            // left out with skip_bad_media
  std::array<std::size_t, 3> fully_occluded{};  // frame-table rows without a pedestrian pixel
  int passes = 0;  // times the file was written: > 1 when a file failed mid-decode (skipped)
};

// When a shard met a media failure (registered with pybind11 as _core.FailurePhase):
// while opening the files (order: plan recording index) or while decoding (order: split
// << 32 | table block). Sorted by (phase, order), failures come in the order in which the
// unsharded converter meets them.
enum class FailurePhase : int { open = 0, decode = 1 };

struct ShardFailure {
  FailurePhase phase = FailurePhase::open;
  std::uint64_t order = 0;
  LeftOutRecording recording;
  ErrorKind kind = ErrorKind::Error;  // the exception's type
};

struct ConvertReport {
  std::size_t rows = 0, recordings = 0;
  std::array<std::size_t, 3> clips{}, recordings_per_split{};
  std::array<std::array<std::size_t, 2>, 3> class_counts{};
  std::vector<std::pair<std::string, std::string>> skipped;  // recording, reason
  std::size_t clips_rejected_out_of_image = 0, clips_dropped_by_balance = 0;
  std::map<std::string, double> seconds;  // per stage
  std::uint32_t source_crc32 = 0;
  std::uint64_t source_bytes = 0;
  std::vector<VerifyRow> verify;         // every recording, when verify is on
  std::vector<std::string> verify_failed;  // recordings beyond tolerance
  MediaReport media;
  std::vector<ShardFailure> shard_failures;  // sharded only
};

// Throws bsp::Error naming the CSV line/column and the path for an absolute media path, one
// with a `..` component, an empty one, or one not found; reader errors (VideoDecodeError,
// ApngError) name the file and frame. With media.skip_bad_media such recordings are left
// out (re-planned without them) and listed in report.media.bad.
ConvertReport convert_csv(const std::string& csv_path, const std::string& out_path,
                          const ConvertOptions& opt, ConvertProgress* progress = nullptr);

// ---- Pedestrian crops (docs/dataset-format.md, "3. Media": tag 4 = Pedestrian) -------
inline constexpr std::uint8_t kPedestrianTag = 4;
inline constexpr int kVisibilityRadius = 2;  // px around round(u, v)
inline constexpr double kCropScale = 1.2;    // side = 1.2 x the larger bbox side (20 % margin)
inline constexpr int kCropMinSize = 32;      // px, before resizing

struct FrameMedia {
  std::array<std::int32_t, 4> mask_bbox{-1, -1, -1, -1};  // [u0, v0, u1, v1), -1 = no tag 4
  std::int64_t visible_pixels = 0;                          // tag-4 pixels in the frame
  std::array<std::uint8_t, 26> joint_visible{};
  // [u0, v0, u1, v1], integer edges, square, may leave the image; all NaN = no crop
  // (CropBoxPolicy::mask on a frame without a pedestrian pixel)
  std::array<float, 4> crop_box{};
  bool has_crop() const { return crop_box[0] == crop_box[0]; }
};

// The pedestrian statistics of one segmentation frame (height x width tags) with its 26
// projected joints `uv` (u, v pairs; non-finite joints are ignored). A joint is visible
// when a tag-4 pixel lies within kVisibilityRadius of (floor(u + 0.5), floor(v + 0.5)).
// The crop box is the square of side max(kCropMinSize, ceil(kCropScale * max(w, h)))
// around the centre of the policy's box (mask bbox, joint bbox U mask bbox, or joint
// bbox), its corner at floor(centre - side/2 + 0.5). Under `mask` a frame without a tag-4
// pixel gets no crop (NaN box); under the others an empty box falls back to the joints,
// then to the image centre.
FrameMedia frame_media(const std::uint8_t* tags, int width, int height, const float* uv,
                       CropBoxPolicy policy = CropBoxPolicy::mask);

// The context box of a crop box: the square of side ceil(context * side - 1e-9) with the
// same centre, corner at u0 - floor((side_c - side) / 2) (integer edges). NaN stays NaN.
std::array<float, 4> context_box(const std::array<float, 4>& box, double context);
// Pixels of the context crop of a crop_size S crop: ceil(context * S - 1e-9).
int context_size(int crop_size, double context);

// Cuts `box` (integer edges, as frame_media makes them) out of an image of which only the
// region roi_x, roi_y, roi_width x roi_height is given (`roi`: rows of roi_width * channels
// bytes), pads the rest with zeros and resizes it to size x size into `out`: INTER_AREA for
// pictures, INTER_NEAREST for class tags (`nearest`).
void crop_resize(const std::uint8_t* roi, int roi_x, int roi_y, int roi_width, int roi_height,
                 int channels, const std::array<float, 4>& box, int size, bool nearest,
                 std::uint8_t* out);

}  // namespace bsp
