// The CARLA-BSP data.csv reader and writer (docs/dataset-format.md, "2. data.csv").
//
// The file is read into a columnar PoseTable: one member per CSV column, numbers in flat
// row-major arrays, strings dictionary-encoded. Reading scans the file once in parallel for
// the row boundaries (quoted cells hold commas but never newlines) and its CRC-32, then
// parses row blocks in parallel straight into the preallocated columns, each thread
// reading its rows a buffer at a time; the result is identical for any thread count. Writing reproduces pandas `DataFrame.to_csv(index=False)` byte for byte.
#pragma once
#include <array>
#include <atomic>
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

namespace bsp {

// A dictionary-encoded string column: the value of row r is values[codes[r]]; values are in
// first-seen order. An empty cell is the empty string.
struct StringColumn {
  std::vector<std::string> values;
  std::vector<std::int32_t> codes;
};

struct PoseTable {
  std::string path;
  std::size_t rows = 0;
  std::uint64_t file_bytes = 0;  // the size of the file read
  std::uint32_t file_crc32 = 0;  // CRC-32 (zlib's) of all its bytes, computed while reading
  std::vector<std::int64_t> line;  // 1-based line of each row in the file (header = line 1)

  StringColumn id, map, model, age, gender, recording, segmentation;
  std::vector<std::int64_t> camera_idx, camera_width, camera_height, pedestrian_idx, frame_idx,
      world_frame;
  // Row-major float32 arrays. An empty list cell reads as NaNs.
  std::vector<float> camera_transform /*rows*6*/, spawn_point /*rows*6*/,
      walker_transform /*rows*6*/, velocity /*rows*3*/, pose_world, pose_component,
      pose_relative /*rows*26*6*/, pose_camera /*rows*26*2*/;
  std::vector<std::uint8_t> is_crossing, in_frame, in_segmentation;  // 0/1
  // 0 = empty cell. For writing, an empty vector means "all valid".
  std::vector<std::uint8_t> is_crossing_valid, in_frame_valid, in_segmentation_valid;

  // Canonical names (kPoseCsvColumns spelling) of the columns that were read, in
  // kPoseCsvColumns order.
  std::vector<std::string> columns_present;
  // The file's own name of the crossing column ("frame.pedestrian.is_crossing" or
  // "frame.pedestrian.is_on_driving_lane"); empty when it was not read.
  std::string crossing_column;
};

// The 24 columns in the original writer's order (docs/dataset-format.md, "2. data.csv").
inline constexpr std::size_t kPoseCsvColumnCount = 24;
extern const std::array<const char*, kPoseCsvColumnCount> kPoseCsvColumns;
// The newer name of column 21, accepted by the reader and by column selection.
inline constexpr const char* kCrossingAlias = "frame.pedestrian.is_on_driving_lane";

struct CsvReadOptions {
  // Names to parse (either crossing name is accepted); empty = all 24. Every requested
  // column must be in the header. With check_duplicates, the four key columns (id,
  // camera.idx, pedestrian.idx, frame.idx) are read too.
  std::vector<std::string> columns;
  int threads = 0;  // 0 = bsp::num_threads()
  bool check_duplicates = true;
  // Optional progress for another thread to poll: the number of data rows once the file
  // is indexed, then the rows parsed so far (updated every few hundred rows).
  std::atomic<std::uint64_t>* rows_total = nullptr;
  std::atomic<std::uint64_t>* rows_done = nullptr;
};

// Throws CsvParseError (file, line, column, what was expected and what was found) for bad
// input, std::invalid_argument for an unknown name in options.columns.
PoseTable read_pose_csv(const std::string& path, const CsvReadOptions& options = {});

// Writes all 24 columns exactly as pandas `to_csv(index=False)` wrote the recorder's
// DataFrame. The file appears atomically (written under a temporary name, then renamed).
// Throws std::invalid_argument when a column has the wrong size, bsp::Error on I/O errors.
void write_pose_csv(const std::string& path, const PoseTable& table, int threads = 0);

// Python's repr() of a double: shortest round-trip digits, exponent notation when the
// decimal exponent is < -4 or >= 16 ("1e-05", "1.5e+16"), ".0" on integral values, "nan",
// "inf", "-inf", "-0.0". `out` needs room for kPyFloatMaxChars; returns the length.
inline constexpr std::size_t kPyFloatMaxChars = 32;
std::size_t format_pyfloat(double v, char* out);

}  // namespace bsp
