// The CARLA-BSP data.csv reader and writer (docs/dataset-format.md, "2. data.csv").
//
// The file is read into a columnar PoseTable: one member per CSV column, numbers in flat
// row-major arrays, strings dictionary-encoded. Reading scans the file once in parallel for
// the row boundaries (quoted cells hold commas but never newlines) and its CRC-32, then
// parses row blocks in parallel straight into the preallocated columns, each thread
// reading its rows a buffer at a time; the result is identical for any thread count. With
// deferred columns (CsvReadOptions::deferred) both happen in one pass: each thread parses
// the rows of its byte range from the buffers it scans, and the parts are joined in order.
// Writing reproduces pandas `DataFrame.to_csv(index=False)` byte for byte.
#pragma once
#include <array>
#include <atomic>
#include <cstddef>
#include <cstdint>
#include <memory>
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

  // Only with CsvReadOptions::deferred (DeferredCells reads them): each row's bytes in the
  // file [row_begin, row_end), the file's modification time, the header's cell count and
  // the deferred columns with the header cell of each, in header order.
  std::vector<std::uint64_t> row_begin, row_end;
  // Bytes from each row's start to its first deferred cell, found while the row was parsed
  // (DeferredCells starts there); empty, or kUnknownSkip for a row, when not known.
  std::vector<std::uint32_t> row_skip;
  static constexpr std::uint32_t kUnknownSkip = 0xFFFFFFFFu;
  std::int64_t file_mtime_ns = 0;
  std::size_t header_cells = 0;
  std::vector<int> deferred_columns, deferred_cells;
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
  // Float list columns (among `columns`) that are only required in the header, not parsed:
  // their cells are skipped and DeferredCells parses them later, row by row. bsp-convert
  // defers the three 26-joint pose columns, 85 % of the file, and parses them while it
  // writes the clips, so the whole table never holds them (half a gigabyte for the
  // published size, most of the conversion's memory and page faults).
  std::vector<std::string> deferred;
};

// Throws CsvParseError (file, line, column, what was expected and what was found) for bad
// input, std::invalid_argument for an unknown name in options.columns.
PoseTable read_pose_csv(const std::string& path, const CsvReadOptions& options = {});

// Thrown by DeferredCells::read for a malformed deferred cell: the caller stops and calls
// DeferredCells::throw_parse_error, which names the file's first bad row.
struct DeferredCellError {};

// The deferred columns of a PoseTable (CsvReadOptions::deferred), parsed from its file on
// demand with the reader's own cell scanners (the same floats, bit for bit, as a plain
// read). Safe to use from several threads at once.
class DeferredCells {
 public:
  // `read_options`: those the table was read with (throw_parse_error reads again with them,
  // nothing deferred). Throws CsvParseError when the file changed since it was read.
  DeferredCells(const PoseTable& table, const CsvReadOptions& read_options);
  ~DeferredCells();
  DeferredCells(const DeferredCells&) = delete;
  DeferredCells& operator=(const DeferredCells&) = delete;
  // Floats per row: the deferred columns' numbers, in kPoseCsvColumns order.
  std::size_t floats_per_row() const { return per_row_; }
  // Offset of column `index` (0..23) within a row's floats; -1 when it is not deferred.
  int offset_of(int index) const;
  // Parses `rows` (indices into the table) into out[k * floats_per_row() ...]; `buf` is the
  // caller's scratch space for the rows' text. DeferredCellError on a malformed cell,
  // CsvParseError when the file changed.
  void read(const std::size_t* rows, std::size_t count, float* out, std::vector<char>& buf) const;
  // The rows no read() call asked for are parsed here too (threads as in parallel_for), so a
  // malformed cell anywhere fails as a plain read would; DeferredCellError then.
  void check_rows(const std::vector<std::uint8_t>& done, int threads) const;
  // Reads the file again without deferring and throws what read_pose_csv throws for its
  // first bad row; a CsvParseError saying the file changed when that read succeeds.
  [[noreturn]] void throw_parse_error() const;

 private:
  struct File;
  const PoseTable& t_;
  CsvReadOptions options_;
  std::size_t per_row_ = 0;
  std::vector<int> offsets_;  // per column (24), -1 when not deferred
  std::unique_ptr<File> file_;
};

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
