// The data.csv schema: column names in the writer's order, their kinds and shapes.
#include <algorithm>
#include <cstdio>

#include "bsp/csv/columns.hpp"
#include "bsp/csv/csv.hpp"
#include "csv_internal.hpp"

namespace bsp {

const std::array<const char*, kPoseCsvColumnCount> kPoseCsvColumns = {
    "id",
    "world.map",
    "camera.idx",
    "camera.transform",
    "camera.width",
    "camera.height",
    "pedestrian.idx",
    "pedestrian.model",
    "pedestrian.age",
    "pedestrian.gender",
    "pedestrian.spawn_point",
    "frame.idx",
    "camera.recording",
    "camera.semantic_segmentation",
    "world.frame",
    "frame.pedestrian.transform",
    "frame.pedestrian.velocity",
    "frame.pedestrian.pose.world",
    "frame.pedestrian.pose.component",
    "frame.pedestrian.pose.relative",
    "frame.pedestrian.is_crossing",
    "frame.pedestrian.pose.camera",
    "frame.pedestrian.pose.in_frame",
    "frame.pedestrian.pose.in_segmentation",
};

namespace {
constexpr CsvColumnSpec str(const char* n) { return {n, CsvKind::string, 0, 0}; }
constexpr CsvColumnSpec integer(const char* n) { return {n, CsvKind::integer, 0, 0}; }
constexpr CsvColumnSpec list(const char* n, std::uint16_t k) { return {n, CsvKind::floats, 0, k}; }
constexpr CsvColumnSpec nested(const char* n, std::uint16_t o, std::uint16_t i) {
  return {n, CsvKind::floats, o, i};
}
constexpr CsvColumnSpec boolean(const char* n) { return {n, CsvKind::boolean, 0, 0}; }
}  // namespace

const CsvColumnSpec kPoseCsvSpecs[kPoseCsvColumnCount] = {
    str("id"),
    str("world.map"),
    integer("camera.idx"),
    list("camera.transform", 6),
    integer("camera.width"),
    integer("camera.height"),
    integer("pedestrian.idx"),
    str("pedestrian.model"),
    str("pedestrian.age"),
    str("pedestrian.gender"),
    list("pedestrian.spawn_point", 6),
    integer("frame.idx"),
    str("camera.recording"),
    str("camera.semantic_segmentation"),
    integer("world.frame"),
    list("frame.pedestrian.transform", 6),
    list("frame.pedestrian.velocity", 3),
    nested("frame.pedestrian.pose.world", 26, 6),
    nested("frame.pedestrian.pose.component", 26, 6),
    nested("frame.pedestrian.pose.relative", 26, 6),
    boolean("frame.pedestrian.is_crossing"),
    nested("frame.pedestrian.pose.camera", 26, 2),
    boolean("frame.pedestrian.pose.in_frame"),
    boolean("frame.pedestrian.pose.in_segmentation"),
};

int pose_csv_column_index(std::string_view name) {
  if (name == kCrossingAlias) return csv_detail::kCrossingColumn;
  for (std::size_t c = 0; c < kPoseCsvColumnCount; ++c)
    if (name == kPoseCsvColumns[c]) return static_cast<int>(c);
  return -1;
}

namespace csv_detail {

std::string allowed_columns() {
  std::string allowed;
  for (const char* n : kPoseCsvColumns) allowed += std::string(allowed.empty() ? "" : ", ") + n;
  return allowed + ", " + kCrossingAlias;
}

std::string snippet(std::string_view text, std::size_t max_chars) {
  // Messages reach Python, which decodes them strictly: bytes of a cell that is not valid
  // UTF-8 are written as \xNN (valid non-ASCII text is kept as it is).
  const bool raw_ok = is_valid_utf8(text.substr(0, std::min(text.size(), max_chars)));
  std::string out = "'";
  for (std::size_t i = 0; i < text.size() && i < max_chars; ++i) {
    const unsigned char c = static_cast<unsigned char>(text[i]);
    if (c == '\\' || c == '\'') {
      out += '\\';
      out += static_cast<char>(c);
    } else if (c < 0x20 || c == 0x7f || (c >= 0x80 && !raw_ok)) {
      char buf[8];
      std::snprintf(buf, sizeof buf, "\\x%02x", c);
      out += buf;
    } else {
      out += static_cast<char>(c);
    }
  }
  if (text.size() > max_chars) out += "...";
  return out + "'";
}

}  // namespace csv_detail
}  // namespace bsp
