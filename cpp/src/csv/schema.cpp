// The data.csv schema: column names in the writer's order, their kinds and shapes, and
// where each lives in a PoseTable.
#include <cstdio>

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

namespace csv_detail {

namespace {
constexpr ColumnSpec str(const char* n) { return {n, Kind::string, 0, 0}; }
constexpr ColumnSpec integer(const char* n) { return {n, Kind::integer, 0, 0}; }
constexpr ColumnSpec list(const char* n, std::uint16_t k) { return {n, Kind::floats, 0, k}; }
constexpr ColumnSpec nested(const char* n, std::uint16_t o, std::uint16_t i) {
  return {n, Kind::floats, o, i};
}
constexpr ColumnSpec boolean(const char* n) { return {n, Kind::boolean, 0, 0}; }
}  // namespace

const ColumnSpec kSpecs[kPoseCsvColumnCount] = {
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

int column_index(std::string_view name) {
  if (name == kCrossingAlias) return kCrossingColumn;
  for (std::size_t c = 0; c < kPoseCsvColumnCount; ++c)
    if (name == kPoseCsvColumns[c]) return static_cast<int>(c);
  return -1;
}

ColumnRef column_ref(PoseTable& t, int col) {
  ColumnRef r;
  switch (col) {
    case 0: r.str = &t.id; break;
    case 1: r.str = &t.map; break;
    case 2: r.ints = &t.camera_idx; break;
    case 3: r.floats = &t.camera_transform; break;
    case 4: r.ints = &t.camera_width; break;
    case 5: r.ints = &t.camera_height; break;
    case 6: r.ints = &t.pedestrian_idx; break;
    case 7: r.str = &t.model; break;
    case 8: r.str = &t.age; break;
    case 9: r.str = &t.gender; break;
    case 10: r.floats = &t.spawn_point; break;
    case 11: r.ints = &t.frame_idx; break;
    case 12: r.str = &t.recording; break;
    case 13: r.str = &t.segmentation; break;
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

std::string snippet(std::string_view text, std::size_t max_chars) {
  std::string out = "'";
  for (std::size_t i = 0; i < text.size() && i < max_chars; ++i) {
    const unsigned char c = static_cast<unsigned char>(text[i]);
    if (c == '\\' || c == '\'') {
      out += '\\';
      out += static_cast<char>(c);
    } else if (c < 0x20 || c == 0x7f) {
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
