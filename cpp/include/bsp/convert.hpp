// bsp-convert: data.csv -> train/val/test clips in one HDF5 file (SPEC sections 3 and 4).
#pragma once
#include <atomic>
#include <cstdint>
#include <map>
#include <string>
#include <vector>

#include "bsp/clips.hpp"

namespace bsp {

struct ConvertOptions {
  ClipOptions clips;
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

// Polled by the Python side from another thread (no callbacks into Python).
struct ConvertProgress {
  std::atomic<int> stage{0};  // 0 read, 1 plan, 2 verify, 3 write, 4 done
  std::atomic<std::uint64_t> done{0}, total{0};
};

struct VerifyRow {
  std::string recording;  // video path without extension + "/<camera>_<pedestrian>"
  double component_mm = 0, world_mm = 0, camera_px = 0;
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
};

ConvertReport convert_csv(const std::string& csv_path, const std::string& out_path,
                          const ConvertOptions& opt, ConvertProgress* progress = nullptr);

}  // namespace bsp
