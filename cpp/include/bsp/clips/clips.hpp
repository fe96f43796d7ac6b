// From rows to clips (docs/dataset-format.md, "7. From rows to clips and splits"):
// recordings, contiguous segments, windows, the in-image filter, labels, the benchmark's
// time-to-event windows, the seeded split by recording and optional train class balancing.
// Pure bookkeeping on row indices: no pose data is copied here.
#pragma once
#include <array>
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

namespace bsp {

// Views into a parsed table, one entry per CSV row.
struct RowKeys {
  std::size_t rows = 0;
  const std::int32_t* id_code = nullptr;  // dictionary code of `id`
  const std::int64_t* camera_idx = nullptr;
  const std::int64_t* pedestrian_idx = nullptr;
  const std::int64_t* frame_idx = nullptr;
  const std::uint8_t* is_crossing = nullptr;  // empty cells count as not crossing
  const float* pose_camera = nullptr;         // rows x joints x 2
  const std::int64_t* width = nullptr;
  const std::int64_t* height = nullptr;
  int joints = 26;
};

struct ClipOptions {
  int length = 30;            // L: frames per clip
  int stride = 0;             // frames between clip starts in train (0 = L, no overlap)
  int eval_stride = 0;        // the same for val/test (0 = stride)
  int min_video_length = 0;   // recordings with fewer rows are skipped (0 = L)
  double label_fraction = 0;  // 0: label = last frame; F > 0: any of the last ceil(L*F)
  bool benchmark = false;     // time-to-event windows, video-level label
  double val_frac = 0.2, test_frac = 0.2;
  std::uint64_t seed = 22742;
  bool balance = false;  // train: keep min(class count) clips of each class
};

struct Recording {
  std::int32_t id_code = 0;
  std::int64_t camera_idx = 0, pedestrian_idx = 0;
  std::vector<std::size_t> rows;  // table rows sorted by frame_idx
  bool crosser = false;           // any row crossing
  std::int64_t event_frame = -1;  // benchmark mode: first crossing frame, else last - 3
};

// Clip::time_to_event of a clip that has no event (not a benchmark window); also the
// value of the clip file's meta/tte then (docs/hdf5-schema.md).
constexpr std::int32_t kNoEvent = -1;

struct Clip {
  std::uint32_t recording = 0;  // index into Plan::recordings
  std::uint32_t first = 0;      // index of the first frame in Recording::rows
  std::int32_t segment = 0;     // contiguous segment of the recording (counts from 0)
  std::int32_t index = 0;       // clip counter, restarting in each segment
  std::uint8_t label = 0;       // 1 = crossing
  // Benchmark mode: frames from the window's last frame to its recording's event
  // (Recording::event_frame - frame_idx of the last row; 30..61 by docs/hdf5-schema.md,
  // "Per split").
  // kNoEvent outside benchmark mode, where a recording has no event.
  std::int32_t time_to_event = kNoEvent;
};

enum SplitId { kTrain = 0, kVal = 1, kTest = 2 };
constexpr std::array<const char*, 3> kSplitNames = {"train", "val", "test"};

struct SkippedRecording {
  std::uint32_t recording;
  std::string reason;
};

struct Plan {
  std::vector<Recording> recordings;
  std::array<std::vector<Clip>, 3> splits;
  std::array<std::vector<std::uint32_t>, 3> split_recordings;  // recordings per split
  std::vector<SkippedRecording> skipped;
  std::size_t clips_rejected_out_of_image = 0;
  std::size_t clips_dropped_by_balance = 0;
};

Plan plan_clips(const RowKeys& keys, const ClipOptions& opt);

// Deterministic generator shared by the split shuffle and tests (SplitMix64).
class SplitMix64 {
 public:
  explicit SplitMix64(std::uint64_t seed) : s_(seed) {}
  std::uint64_t next();
  std::uint64_t below(std::uint64_t n);  // uniform in [0, n), unbiased
 private:
  std::uint64_t s_;
};

}  // namespace bsp
