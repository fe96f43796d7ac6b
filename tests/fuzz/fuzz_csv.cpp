// libFuzzer harness for the data.csv reader (cpp/src/csv): the input is the whole file.
// Every outcome but a PoseTable or a CsvParseError is a finding: a sanitizer report, a
// crash, or any other exception (std::bad_alloc, std::length_error, ...) escaping.
#include <algorithm>
#include <cstdint>
#include <cstdlib>
#include <string>
#include <vector>

#include "bsp/common/errors.hpp"
#include "bsp/csv/csv.hpp"
#include "fuzz_file.hpp"

namespace {
// A read's outcome: its rows, CRC-32 and line numbers, or its error (first: '!').
std::string outcome(const std::string& path, const bsp::CsvReadOptions& opt) {
  try {
    const bsp::PoseTable t = bsp::read_pose_csv(path, opt);
    std::string s = std::to_string(t.rows) + " " + std::to_string(t.file_crc32);
    for (const std::int64_t line : t.line) s += " " + std::to_string(line);
    return s;
  } catch (const bsp::CsvParseError& e) {
    return std::string("!") + e.what();
  }
}

// bsp-convert's read, the pose columns deferred (one pass over the file, csv/rows.cpp),
// gives what the two-pass read of the other columns gives (its cells skipped the same
// way), but for a header without the pose columns, which only it requires.
void check_deferred(const std::string& path) {
  bsp::CsvReadOptions others, deferred;
  others.threads = deferred.threads = 1;
  const std::vector<std::string> poses = {"frame.pedestrian.pose.world",
                                          "frame.pedestrian.pose.component",
                                          "frame.pedestrian.pose.relative"};
  for (const char* name : bsp::kPoseCsvColumns) {
    const bool pose = std::find(poses.begin(), poses.end(), name) != poses.end();
    if (!pose) others.columns.emplace_back(name);
    deferred.columns.emplace_back(name);
  }
  deferred.deferred = poses;
  const std::string a = outcome(path, others), b = outcome(path, deferred);
  if (a != b && b.find("line 1 (header)") == std::string::npos) std::abort();
}
}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  static bsp::fuzz::MemFile file("data.csv");
  const std::string& path = file.write(data, size);
  check_deferred(path);
  bsp::CsvReadOptions opt;
  opt.threads = 1;  // deterministic and fast; tests/cpp/test_csv.cpp covers the thread counts
  try {
    const bsp::PoseTable t = bsp::read_pose_csv(path, opt);
    // The table's invariants the converter relies on.
    if (t.line.size() != t.rows || t.frame_idx.size() != t.rows || t.id.codes.size() != t.rows)
      std::abort();
    for (std::size_t r = 0; r < t.rows; ++r) {
      if (t.frame_idx[r] < 0 || t.camera_width[r] < 1 || t.camera_height[r] < 1) std::abort();
      if (t.id.codes[r] < 0 || std::size_t(t.id.codes[r]) >= t.id.values.size()) std::abort();
    }
  } catch (const bsp::CsvParseError&) {
  }
  return 0;
}
