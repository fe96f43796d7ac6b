// libFuzzer harness for the data.csv reader (cpp/src/csv): the input is the whole file.
// Every outcome but a PoseTable or a CsvParseError is a finding: a sanitizer report, a
// crash, or any other exception (std::bad_alloc, std::length_error, ...) escaping.
#include <cstdint>
#include <cstdlib>

#include "bsp/common/errors.hpp"
#include "bsp/csv/csv.hpp"
#include "fuzz_file.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  static bsp::fuzz::MemFile file("data.csv");
  const std::string& path = file.write(data, size);
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
