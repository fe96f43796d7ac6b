// A PoseTable column by column: where each column lives, its array shape, and the UTF-8
// check of the string columns.
#include <cstdio>
#include <stdexcept>
#include <string>

#include "bsp/common/errors.hpp"
#include "bsp/csv/columns.hpp"
#include "bsp/csv/csv.hpp"
#include "csv_internal.hpp"

namespace bsp {

std::vector<std::size_t> CsvColumnSpec::shape(std::size_t rows) const {
  if (kind != CsvKind::floats) return {rows};
  if (outer) return {rows, outer, inner};
  return {rows, inner};
}

PoseColumn pose_column(PoseTable& t, std::size_t index) {
  if (index >= kPoseCsvColumnCount)
    throw std::out_of_range("pose_column: index " + std::to_string(index) + " is not below " +
                            std::to_string(kPoseCsvColumnCount));
  PoseColumn r;
  r.spec = &kPoseCsvSpecs[index];
  switch (index) {
    case 0: r.strings = &t.id; break;
    case 1: r.strings = &t.map; break;
    case 2: r.ints = &t.camera_idx; break;
    case 3: r.floats = &t.camera_transform; break;
    case 4: r.ints = &t.camera_width; break;
    case 5: r.ints = &t.camera_height; break;
    case 6: r.ints = &t.pedestrian_idx; break;
    case 7: r.strings = &t.model; break;
    case 8: r.strings = &t.age; break;
    case 9: r.strings = &t.gender; break;
    case 10: r.floats = &t.spawn_point; break;
    case 11: r.ints = &t.frame_idx; break;
    case 12: r.strings = &t.recording; break;
    case 13: r.strings = &t.segmentation; break;
    case 14: r.ints = &t.world_frame; break;
    case 15: r.floats = &t.walker_transform; break;
    case 16: r.floats = &t.velocity; break;
    case 17: r.floats = &t.pose_world; break;
    case 18: r.floats = &t.pose_component; break;
    case 19: r.floats = &t.pose_relative; break;
    case 20: r.bools = &t.is_crossing, r.valid = &t.is_crossing_valid; break;
    case 21: r.floats = &t.pose_camera; break;
    case 22: r.bools = &t.in_frame, r.valid = &t.in_frame_valid; break;
    case 23: r.bools = &t.in_segmentation, r.valid = &t.in_segmentation_valid; break;
    default: break;
  }
  return r;
}

PoseColumn pose_column(PoseTable& t, std::string_view name) {
  const int c = pose_csv_column_index(name);
  if (c < 0)
    throw std::invalid_argument("pose_column: unknown column '" + std::string(name) +
                                "'; allowed: " + csv_detail::allowed_columns());
  return pose_column(t, static_cast<std::size_t>(c));
}

// Table 3-7 of the Unicode standard (well-formed byte sequences), which is exactly what
// Python's strict UTF-8 decoder accepts.
bool is_valid_utf8(std::string_view s) {
  const auto* p = reinterpret_cast<const unsigned char*>(s.data());
  const unsigned char* end = p + s.size();
  while (p < end) {
    const unsigned char c = *p;
    if (c < 0x80) {
      ++p;
      continue;
    }
    int n = 0;  // continuation bytes
    unsigned char lo = 0x80, hi = 0xBF;  // range of the first continuation byte
    if (c >= 0xC2 && c <= 0xDF) n = 1;
    else if (c == 0xE0) n = 2, lo = 0xA0;
    else if ((c >= 0xE1 && c <= 0xEC) || c == 0xEE || c == 0xEF) n = 2;
    else if (c == 0xED) n = 2, hi = 0x9F;  // no surrogates
    else if (c == 0xF0) n = 3, lo = 0x90;
    else if (c >= 0xF1 && c <= 0xF3) n = 3;
    else if (c == 0xF4) n = 3, hi = 0x8F;  // nothing above U+10FFFF
    else return false;                     // 0x80..0xC1 (continuation, overlong), 0xF5..
    if (end - p <= n) return false;
    if (p[1] < lo || p[1] > hi) return false;
    for (int k = 2; k <= n; ++k)
      if (p[k] < 0x80 || p[k] > 0xBF) return false;
    p += n + 1;
  }
  return true;
}

namespace {
// The message must itself be valid UTF-8 (Python decodes it): bytes >= 0x80 as \xNN.
std::string ascii_snippet(std::string_view text) {
  std::string out;
  for (const char ch : csv_detail::snippet(text)) {
    const auto c = static_cast<unsigned char>(ch);
    if (c < 0x80) {
      out += ch;
      continue;
    }
    char buf[8];
    std::snprintf(buf, sizeof buf, "\\x%02x", c);
    out += buf;
  }
  return out;
}
}  // namespace

void check_utf8(const PoseTable& t) {
  // pose_column hands out mutable pointers; this only reads through them.
  PoseTable& table = const_cast<PoseTable&>(t);
  for (const std::string& name : t.columns_present) {
    const PoseColumn col = pose_column(table, name);
    if (!col.strings) continue;
    for (std::size_t k = 0; k < col.strings->values.size(); ++k) {
      const std::string& v = col.strings->values[k];
      if (is_valid_utf8(v)) continue;
      // Codes are first-seen: the first row holding code k is its first line in the file.
      std::string line;
      for (std::size_t r = 0; r < t.rows && r < t.line.size(); ++r)
        if (col.strings->codes[r] == static_cast<std::int32_t>(k)) {
          line = ", line " + std::to_string(t.line[r]);
          break;
        }
      throw CsvParseError(t.path + line + ", column '" + col.spec->name + "': value " +
                          ascii_snippet(v) + " is not valid UTF-8");
    }
  }
}

}  // namespace bsp
