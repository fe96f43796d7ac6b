#include <doctest/doctest.h>
#include <unistd.h>
#include <zlib.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <random>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "bsp/common/errors.hpp"
#include "bsp/csv/columns.hpp"
#include "bsp/csv/csv.hpp"
#include "csv/csv_internal.hpp"  // white-box: the number fast path
#include "pyfloat_repr_cases.hpp"
#include "testing.hpp"

using namespace bsp;
using bsp::testing::kReprCases;
using bsp::testing::ReprCase;
using bsp::testing::TempDir;
namespace fs = std::filesystem;

namespace {

std::string pyfloat(double v) {
  char buf[kPyFloatMaxChars];
  return std::string(buf, format_pyfloat(v, buf));
}

std::string number_list(std::size_t n, float base) {
  std::string s = "[";
  for (std::size_t i = 0; i < n; ++i) s += (i ? ", " : "") + pyfloat(base + 0.25f * i);
  return s + "]";
}

std::string nested_list(std::size_t outer, std::size_t inner, float base) {
  std::string s = "[";
  for (std::size_t j = 0; j < outer; ++j)
    s += (j ? ", " : "") + number_list(inner, base + static_cast<float>(j));
  return s + "]";
}

// A cell as pandas quotes it.
std::string csvq(const std::string& s) {
  if (s.find_first_of(",\"") == std::string::npos) return s;
  std::string q = "\"";
  for (char c : s) q += c == '"' ? std::string("\"\"") : std::string(1, c);
  return q + "\"";
}

// The 24 cells of a valid row in writer order; frame picks frame.idx and the numbers.
std::vector<std::string> row_cells(int frame, const std::string& id = "clip-a") {
  const float b = static_cast<float>(frame);
  const auto q = [](const std::string& s) { return "\"" + s + "\""; };
  return {csvq(id), "/Game/Carla/Maps/Town04", "0", q(number_list(6, b)), "1600", "600", "0",
          "walker.pedestrian.0001", "adult", "female", q(number_list(6, 1 + b)),
          std::to_string(frame), csvq("clips/" + id + "-0.mp4"), csvq("clips/" + id + "-1.apng"), "100",
          q(number_list(6, 2 + b)), q(number_list(3, 3 + b)), q(nested_list(26, 6, 4 + b)),
          q(nested_list(26, 6, 5 + b)), q(nested_list(26, 6, 6 + b)), "True",
          q(nested_list(26, 2, 7 + b)), "False", ""};
}

std::string join(const std::vector<std::string>& cells, const char* eol = "\n") {
  std::string s;
  for (std::size_t k = 0; k < cells.size(); ++k) s += (k ? "," : "") + cells[k];
  return s + eol;
}

std::string header_line() {
  return join(std::vector<std::string>(kPoseCsvColumns.begin(), kPoseCsvColumns.end()));
}

std::string error_of(const std::string& path, const CsvReadOptions& opt = {}) {
  try {
    read_pose_csv(path, opt);
  } catch (const CsvParseError& e) {
    return e.what();
  }
  return "no error";
}

}  // namespace

TEST_CASE("format_pyfloat matches Python's repr") {
  for (const ReprCase& c : kReprCases) {
    double v;
    std::memcpy(&v, &c.bits, sizeof v);
    CHECK_MESSAGE(pyfloat(v) == c.repr, c.repr);
  }
}

TEST_CASE("format_pyfloat round-trips random float32 values") {
  std::mt19937 rng(5);
  std::uniform_int_distribution<std::uint32_t> bits;
  for (int i = 0; i < 20000; ++i) {
    std::uint32_t b = bits(rng);
    float f;
    std::memcpy(&f, &b, sizeof f);
    if (!std::isfinite(f)) continue;
    const std::string s = pyfloat(static_cast<double>(f));
    REQUIRE(std::strtod(s.c_str(), nullptr) == static_cast<double>(f));
  }
}

TEST_CASE("the number fast path is bit-identical to fast_float::from_chars") {
  std::vector<std::string> cases = {
      "0.0", "-0.0", "90.0", "-90.0", "1e-05", "0.0001", "0.00012345678901234567",
      "123456789012345.0", "1234567.25", "12345678.0", "1.100000023841858", "-8.130000114440918",
      "nan", "-nan", "inf", "-inf", "9.99994610111476e-41", "3.4028234663852886e+38", "3.5e+38",
      "0.1", "1.", ".5", "-", "-x", "1.0000000596046448", "1.0000000596046447",  // float midpoints
      "1.00000005960464477539", "16777217.0", "0.000000000000000000001", "99999999.5"};
  std::mt19937 rng(11);
  std::uniform_int_distribution<std::uint32_t> bits;
  std::uniform_real_distribution<double> uni(-2000, 2000);
  char buf[kPyFloatMaxChars];
  for (int i = 0; i < 200000; ++i) {
    const std::uint32_t b = bits(rng);
    float f;
    std::memcpy(&f, &b, sizeof f);
    cases.emplace_back(buf, format_pyfloat(static_cast<double>(f), buf));
    cases.emplace_back(buf, format_pyfloat(uni(rng), buf));  // not float32-exact: must round
  }
  // Decimals at and next to float rounding boundaries (midpoints between two floats, exact
  // in a double): where the fast path's double division is not enough to decide.
  for (int i = 0; i < 30000; ++i) {
    const float f = static_cast<float>(uni(rng));
    const double mid = (static_cast<double>(f) + std::nextafter(f, INFINITY)) / 2;
    for (double d : {mid, std::nextafter(mid, 0.0), std::nextafter(mid, 1e9)})
      cases.emplace_back(buf, format_pyfloat(d, buf));
  }
  for (const std::string& c : cases) {
    const std::string text = c + ", 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0]";
    const char* end = text.data() + text.size();
    const char* p1 = text.data();
    const char* p2 = text.data();
    float a = -1, b = -1;
    const bool ok1 = csv_detail::parse_float_generic(p1, end, a);
    const bool ok2 = csv_detail::parse_float(p2, end, b);
    REQUIRE_MESSAGE(ok1 == ok2, c);
    REQUIRE_MESSAGE(p1 == p2, c);
    REQUIRE_MESSAGE(std::memcmp(&a, &b, sizeof a) == 0, c);
  }
}

TEST_CASE("read_pose_csv parses a tiny file") {
  TempDir tmp;
  std::string text = header_line() + join(row_cells(3)) + join(row_cells(5));
  const std::string path = tmp.write("data.csv", text);
  const PoseTable t = read_pose_csv(path);
  REQUIRE(t.rows == 2);
  CHECK(t.line == std::vector<std::int64_t>{2, 3});
  CHECK(t.frame_idx == std::vector<std::int64_t>{3, 5});
  CHECK(t.camera_width[1] == 1600);
  CHECK(t.id.values == std::vector<std::string>{"clip-a"});
  CHECK(t.id.codes == std::vector<std::int32_t>{0, 0});
  CHECK(t.map.values[0] == "/Game/Carla/Maps/Town04");
  CHECK(t.camera_transform[0] == 3.0f);
  CHECK(t.camera_transform[5] == 3.0f + 1.25f);
  CHECK(t.velocity.size() == 6);
  CHECK(t.velocity[3] == 8.0f);
  // pose.world of row 1, joint 25, value 5: base 4 + 5 + 25 + 0.25 * 5.
  CHECK(t.pose_world[1 * 156 + 25 * 6 + 5] == 4 + 5 + 25 + 1.25f);
  CHECK(t.pose_camera[1 * 52 + 2 * 2 + 1] == 7 + 5 + 2 + 0.25f);
  CHECK(t.is_crossing == std::vector<std::uint8_t>{1, 1});
  CHECK(t.in_frame == std::vector<std::uint8_t>{0, 0});
  CHECK(t.in_frame_valid == std::vector<std::uint8_t>{1, 1});
  CHECK(t.in_segmentation_valid == std::vector<std::uint8_t>{0, 0});
  CHECK(t.columns_present.size() == kPoseCsvColumnCount);
  CHECK(t.crossing_column == "frame.pedestrian.is_crossing");
}

TEST_CASE("read_pose_csv goes by name: reordered columns, alias, CRLF, blank lines, NaN") {
  TempDir tmp;
  std::vector<std::string> names(kPoseCsvColumns.begin(), kPoseCsvColumns.end());
  names[20] = kCrossingAlias;
  names.push_back("extra");
  std::vector<std::string> cells = row_cells(7);
  cells[21] = "\"[[nan, nan], [inf, -inf]";
  for (int j = 2; j < 26; ++j) cells[21] += ", [1e-05, 2.5]";
  cells[21] += "]\"";
  cells[23] = "True";
  cells.push_back("\"ignored, text\"");
  // Reverse the column order.
  std::reverse(names.begin(), names.end());
  std::reverse(cells.begin(), cells.end());
  const std::string text = join(names, "\r\n") + "\r\n" + join(cells, "\r\n") + "\r\n";
  const PoseTable t = read_pose_csv(tmp.write("r.csv", text));
  REQUIRE(t.rows == 1);
  CHECK(t.line[0] == 3);
  CHECK(t.crossing_column == kCrossingAlias);
  CHECK(t.is_crossing[0] == 1);
  CHECK(std::isnan(t.pose_camera[0]));
  CHECK(std::isinf(t.pose_camera[2]));
  CHECK(t.pose_camera[3] < 0);
  CHECK(t.pose_camera[4] == 1e-05f);
  CHECK(t.in_segmentation[0] == 1);
  CHECK(t.in_segmentation_valid[0] == 1);
  CHECK(t.frame_idx[0] == 7);
  CHECK(t.recording.values[0] == "clips/clip-a-0.mp4");
}

TEST_CASE("read_pose_csv reads only the requested columns") {
  TempDir tmp;
  const std::string path = tmp.write("d.csv", header_line() + join(row_cells(1)));
  CsvReadOptions opt;
  opt.columns = {"frame.pedestrian.pose.world", kCrossingAlias};
  opt.check_duplicates = false;
  const PoseTable t = read_pose_csv(path, opt);
  CHECK(t.pose_world.size() == 156);
  CHECK(t.is_crossing.size() == 1);
  CHECK(t.pose_relative.empty());
  CHECK(t.id.codes.empty());
  CHECK(t.columns_present ==
        std::vector<std::string>{"frame.pedestrian.pose.world", "frame.pedestrian.is_crossing"});
  opt.columns = {"no.such.column"};
  CHECK_THROWS_AS(read_pose_csv(path, opt), std::invalid_argument);
}

TEST_CASE("write_pose_csv then read_pose_csv round-trips, for any thread count") {
  TempDir tmp;
  std::string text = header_line();
  for (int f = 0; f < 300; ++f) text += join(row_cells(f, f < 150 ? "clip-a" : "clip, \"b\""));
  const std::string src = tmp.write("src.csv", text);
  CsvReadOptions one, two;
  one.threads = 1;
  two.threads = 2;
  const PoseTable a = read_pose_csv(src, one), b = read_pose_csv(src, two);
  CHECK(a.id.values == std::vector<std::string>{"clip-a", "clip, \"b\""});
  CHECK(a.id.codes == b.id.codes);
  CHECK(a.recording.values == b.recording.values);
  CHECK(a.pose_world == b.pose_world);
  CHECK(a.pose_camera == b.pose_camera);
  CHECK(a.frame_idx == b.frame_idx);
  const std::string out = (tmp.dir / "out.csv").string();
  // The hand-written cells are what pandas writes, so the writer must reproduce them.
  write_pose_csv(out, a, 2);
  std::ifstream in(out, std::ios::binary);
  std::stringstream ss;
  ss << in.rdbuf();
  CHECK(ss.str() == text);
  write_pose_csv(out, b, 1);
  std::ifstream in2(out, std::ios::binary);
  std::stringstream ss2;
  ss2 << in2.rdbuf();
  CHECK(ss2.str() == text);
  // Only data.csv and out.csv: no temporary file (.out.csv.tmp-PID-N) is left behind.
  CHECK(std::distance(fs::directory_iterator(tmp.dir), fs::directory_iterator()) == 2);
}

TEST_CASE("read_pose_csv errors name the file, line, column, expected and found") {
  TempDir tmp;
  const std::string head = header_line();
  const auto with = [&](int col, const std::string& cell) {
    std::vector<std::string> cells = row_cells(2);
    cells[static_cast<std::size_t>(col)] = cell;
    return head + join(row_cells(1)) + join(cells);
  };
  SUBCASE("missing column") {
    std::vector<std::string> names(kPoseCsvColumns.begin(), kPoseCsvColumns.end() - 1);
    const std::string p = tmp.write("m.csv", join(names));
    const std::string e = error_of(p);
    CHECK(e.find(p + ", line 1 (header): missing required column "
                     "'frame.pedestrian.pose.in_segmentation'") != std::string::npos);
  }
  SUBCASE("wrong number of lists") {
    const std::string p = tmp.write("l.csv", with(17, "\"" + nested_list(25, 6, 0) + "\""));
    CHECK(error_of(p) == p + ", line 3, column 'frame.pedestrian.pose.world': expected 26 x 6 "
                             "numbers, got 25 lists");
  }
  SUBCASE("wrong inner length") {
    std::string cell = nested_list(26, 6, 0);
    cell.replace(cell.find("], ["), 0, ", 9.0");
    const std::string p = tmp.write("i.csv", with(19, "\"" + cell + "\""));
    CHECK(error_of(p) == p + ", line 3, column 'frame.pedestrian.pose.relative': expected 26 x "
                             "6 numbers, got 7 numbers in list 1");
  }
  SUBCASE("flat list length") {
    const std::string p = tmp.write("f.csv", with(16, "\"[1.0, 2.0]\""));
    CHECK(error_of(p) == p + ", line 3, column 'frame.pedestrian.velocity': expected 3 numbers, "
                             "got 2 numbers");
  }
  SUBCASE("bad number") {
    std::string cell = nested_list(26, 2, 0);
    cell.replace(cell.find("3.0"), 3, "3.x");
    const std::string p = tmp.write("n.csv", with(21, "\"" + cell + "\""));
    CHECK(error_of(p) == p + ", line 3, column 'frame.pedestrian.pose.camera': expected a number "
                             "in list 4 at item 1, found '3.x'");
  }
  SUBCASE("unquoted list") {
    const std::string p = tmp.write("u.csv", with(16, "[1.0, 2.0, 3.0]"));
    CHECK(error_of(p) == p + ", line 3, column 'frame.pedestrian.velocity': expected a "
                             "double-quoted list \"[...]\", found '[1.0'");
  }
  SUBCASE("bad int and bad bool") {
    std::string p = tmp.write("b.csv", with(11, "12a"));
    CHECK(error_of(p) == p + ", line 3, column 'frame.idx': expected an integer, found '12a'");
    p = tmp.write("c.csv", with(22, "yes"));
    CHECK(error_of(p) == p + ", line 3, column 'frame.pedestrian.pose.in_frame': expected True, "
                             "False or an empty cell, found 'yes'");
  }
  SUBCASE("truncated last line") {
    std::string text = head + join(row_cells(1)) + join(row_cells(2));
    text.resize(text.size() - 300);
    const std::string p = tmp.write("t.csv", text);
    const std::string e = error_of(p);
    INFO(e);
    CHECK(e.find(p + ", line 3, column 'frame.pedestrian.pose.") == 0);
    CHECK(e.find("unterminated quote") != std::string::npos);
    CHECK(e.find("no line end: is the file truncated?") != std::string::npos);
  }
  SUBCASE("wrong number of cells") {
    std::vector<std::string> cells = row_cells(2);
    cells.pop_back();
    cells.pop_back();
    std::string p = tmp.write("w.csv", head + join(cells));
    CHECK(error_of(p) == p + ", line 2, column 'frame.pedestrian.pose.in_frame': expected 24 "
                             "cells, found 22 (the row ends before this column)");
    cells = row_cells(2);
    cells.push_back("x");
    p = tmp.write("x.csv", head + join(cells));
    CHECK(error_of(p) == p + ", line 2, column 'frame.pedestrian.pose.in_segmentation': expected "
                             "24 cells, found 25 (extra text after the last column: 'x')");
  }
  SUBCASE("duplicate key") {
    const std::string p =
        tmp.write("d.csv", head + join(row_cells(1)) + join(row_cells(2)) + "\n" +
                               join(row_cells(1)));
    CHECK(error_of(p) == p + ", line 5, columns (id, camera.idx, pedestrian.idx, frame.idx): "
                             "duplicate key ('clip-a', 0, 0, 1): expected each key once, found "
                             "it on line 2 and line 5");
    CsvReadOptions opt;
    opt.check_duplicates = false;
    CHECK(read_pose_csv(p, opt).rows == 3);
  }
  SUBCASE("missing file") {
    CHECK(error_of((tmp.dir / "nope.csv").string()).find("cannot open") != std::string::npos);
  }
}

TEST_CASE("read_pose_csv refuses negative or absurd integers, naming the line (issue 15)") {
  TempDir tmp;
  const auto with = [&](int col, const std::string& cell) {
    std::vector<std::string> cells = row_cells(2);
    cells[static_cast<std::size_t>(col)] = cell;
    return header_line() + join(row_cells(1)) + join(cells);
  };
  SUBCASE("frame.idx") {
    std::string p = tmp.write("neg.csv", with(11, "-5"));
    CHECK(error_of(p) == p + ", line 3, column 'frame.idx': expected a frame index from 0 to "
                             "10000000, found '-5' (out of range: too small)");
    p = tmp.write("big.csv", with(11, "9223372036854775807"));
    CHECK(error_of(p) == p + ", line 3, column 'frame.idx': expected a frame index from 0 to "
                             "10000000, found '9223372036854775807' (out of range: too large)");
    p = tmp.write("ok.csv", with(11, "10000000"));
    CHECK(read_pose_csv(p).frame_idx[1] == 10000000);
  }
  SUBCASE("camera.width and camera.height (item 10)") {
    for (const char* bad : {"0", "-1600", "100000"}) {
      std::string p = tmp.write("w.csv", with(4, bad));
      std::string e = error_of(p);
      INFO(e);
      CHECK(e.find(p + ", line 3, column 'camera.width': expected a picture size in pixels "
                       "from 1 to 16384, found '" + std::string(bad) + "'") == 0);
      p = tmp.write("h.csv", with(5, bad));
      e = error_of(p);
      CHECK(e.find(p + ", line 3, column 'camera.height': expected a picture size") == 0);
    }
  }
  SUBCASE("the other integer columns") {
    for (int col : {2, 6, 14}) {
      const std::string p = tmp.write("o.csv", with(col, "-1"));
      const std::string e = error_of(p);
      INFO(e);
      CHECK(e.find(p + ", line 3, column '" + kPoseCsvColumns[static_cast<std::size_t>(col)] +
                   "': expected ") == 0);
      CHECK(e.find("found '-1' (out of range: too small)") != std::string::npos);
    }
  }
  SUBCASE("the range holds for every thread count") {
    std::string text = header_line();
    for (int f = 0; f < 500; ++f) text += join(row_cells(f));
    std::vector<std::string> cells = row_cells(500);
    cells[11] = "-3";
    text += join(cells);
    const std::string p = tmp.write("many.csv", text);
    for (int threads : {1, 3}) {
      CsvReadOptions opt;
      opt.threads = threads;
      CHECK(error_of(p, opt).find(p + ", line 502, column 'frame.idx'") == 0);
    }
  }
}

TEST_CASE("read_pose_csv refuses CR-only line ends instead of reading zero rows (issue 15)") {
  TempDir tmp;
  const std::string text = join(std::vector<std::string>(kPoseCsvColumns.begin(),
                                                         kPoseCsvColumns.end()), "\r") +
                           join(row_cells(1), "\r") + join(row_cells(2), "\r");
  const std::string p = tmp.write("cr.csv", text);
  const std::string e = error_of(p);
  INFO(e);
  CHECK(e.find(p + ", line 1 (header): found a carriage return without a line feed at byte " +
               std::to_string(header_line().size() - 1) + ": CR-only line ends") == 0);
  // CRLF files still read.
  const std::string q = tmp.write("crlf.csv", join(std::vector<std::string>(
      kPoseCsvColumns.begin(), kPoseCsvColumns.end()), "\r\n") + join(row_cells(1), "\r\n"));
  CHECK(read_pose_csv(q).rows == 1);
}

TEST_CASE("a read past the end of a file truncated while it is read is caught (issue 15)") {
  TempDir tmp;
  const std::size_t size = std::size_t{1} << 16;
  const std::string p = tmp.write("shrinks.csv", std::string(size, 'x'));
  const csv_detail::InputFile file(p);
  REQUIRE(file.size() == size);
  char c[2] = {0, 0};
  file.read(40000, 2, c);
  CHECK(c[0] == 'x');
  CHECK_NOTHROW(file.check_unchanged());
  REQUIRE(::truncate(p.c_str(), 100) == 0);  // another process cuts the file
  CHECK_THROWS_AS(file.read(40000, 2, c), csv_detail::FileChanged);  // not a SIGBUS
  CHECK_THROWS_AS(file.read(99, 2, c), csv_detail::FileChanged);     // ends inside the read
  file.read(10, 2, c);                                                // still readable
  CHECK(c[0] == 'x');
  CHECK_THROWS_AS(file.check_unchanged(), csv_detail::FileChanged);
}

TEST_CASE("the reader's CRC-32 and size are those of the whole file, for any thread count") {
  TempDir tmp;
  std::string text = header_line();  // over 12 MB: three threads scan a range each
  for (int i = 1; text.size() < (std::size_t{13} << 20); ++i) text += join(row_cells(i));
  const std::string p = tmp.write("crc.csv", text);
  const auto expected = static_cast<std::uint32_t>(
      crc32(0, reinterpret_cast<const Bytef*>(text.data()), static_cast<uInt>(text.size())));
  for (int threads : {1, 2, 3}) {
    CsvReadOptions o;
    o.threads = threads;
    const PoseTable t = read_pose_csv(p, o);
    CHECK(t.file_bytes == text.size());
    CHECK(t.file_crc32 == expected);
  }
}

TEST_CASE("a non-UTF-8 byte in a number cell gives an error message that is valid UTF-8") {
  TempDir tmp;
  std::vector<std::string> cells = row_cells(2);
  cells[11] = "1\xff";
  const std::string p = tmp.write("b.csv", header_line() + join(row_cells(1)) + join(cells));
  const std::string e = error_of(p);
  CHECK(e == p + ", line 3, column 'frame.idx': expected an integer, found '1\\xff'");
  CHECK(is_valid_utf8(e));
  cells[11] = "2";
  cells[0] = "caf\xc3\xa9";  // valid UTF-8 stays readable in messages
  cells[4] = "0";
  const std::string q = tmp.write("c.csv", header_line() + join(row_cells(1)) + join(cells));
  CHECK(error_of(q).find("found '0'") != std::string::npos);
}

TEST_CASE("read_pose_csv reports its progress in rows") {
  TempDir tmp;
  std::string text = header_line();
  for (int f = 0; f < 700; ++f) text += join(row_cells(f));
  const std::string path = tmp.write("data.csv", text);
  for (int threads : {1, 2}) {
    std::atomic<std::uint64_t> total{0}, done{0};
    CsvReadOptions opt;
    opt.threads = threads;
    opt.rows_total = &total;
    opt.rows_done = &done;
    const PoseTable t = read_pose_csv(path, opt);
    CHECK(t.rows == 700);
    CHECK(total.load() == 700);
    CHECK(done.load() == 700);
  }
}

TEST_CASE("pose_column: each column's kind, shape and PoseTable member, by name or index") {
  CHECK(pose_csv_column_index("id") == 0);
  CHECK(pose_csv_column_index("frame.pedestrian.is_crossing") == 20);
  CHECK(pose_csv_column_index(kCrossingAlias) == 20);
  CHECK(pose_csv_column_index("no.such.column") == -1);
  PoseTable t;
  const PoseColumn uv = pose_column(t, "frame.pedestrian.pose.camera");
  CHECK(uv.floats == &t.pose_camera);
  CHECK((!uv.strings && !uv.ints && !uv.bools && !uv.valid));
  CHECK(uv.spec->kind == CsvKind::floats);
  CHECK(uv.spec->numbers() == 52);
  CHECK(uv.spec->shape(5) == std::vector<std::size_t>{5, 26, 2});
  CHECK(pose_column(t, "camera.transform").spec->shape(5) == std::vector<std::size_t>{5, 6});
  const PoseColumn crossing = pose_column(t, kCrossingAlias);
  CHECK(std::string(crossing.spec->name) == "frame.pedestrian.is_crossing");
  CHECK((crossing.bools == &t.is_crossing && crossing.valid == &t.is_crossing_valid));
  CHECK(crossing.spec->shape(5) == std::vector<std::size_t>{5});
  CHECK(pose_column(t, "id").strings == &t.id);
  CHECK(pose_column(t, "pedestrian.gender").strings == &t.gender);
  CHECK(pose_column(t, "frame.idx").ints == &t.frame_idx);
  // Every column has its own member and the kind its spec says, in kPoseCsvColumns order.
  std::vector<const void*> homes;
  for (std::size_t c = 0; c < kPoseCsvColumnCount; ++c) {
    const PoseColumn col = pose_column(t, c);
    CHECK(std::string(col.spec->name) == kPoseCsvColumns[c]);
    const CsvKind kind = col.spec->kind;
    CHECK((col.strings != nullptr) == (kind == CsvKind::string));
    CHECK((col.ints != nullptr) == (kind == CsvKind::integer));
    CHECK((col.floats != nullptr) == (kind == CsvKind::floats));
    CHECK(((col.bools != nullptr) && (col.valid != nullptr)) == (kind == CsvKind::boolean));
    homes.push_back(col.strings ? static_cast<const void*>(col.strings)
                    : col.ints  ? static_cast<const void*>(col.ints)
                    : col.floats ? static_cast<const void*>(col.floats)
                                 : static_cast<const void*>(col.bools));
  }
  std::sort(homes.begin(), homes.end());
  CHECK(std::unique(homes.begin(), homes.end()) == homes.end());
  CHECK_THROWS_AS(pose_column(t, std::size_t{24}), std::out_of_range);
  CHECK_THROWS_WITH_AS(pose_column(t, "no.such.column"),
                       doctest::Contains("unknown column 'no.such.column'; allowed: id, "),
                       std::invalid_argument);
}

TEST_CASE("UTF-8 check: Python's strict decoder's rules, and the first bad string is named") {
  for (const char* ok : {"plain", "caf\xc3\xa9 \xe2\x82\xac \xf0\x9f\x9a\xb6", "\xc2\x80",
                         "\xe0\xa0\x80", "\xed\x9f\xbf", "\xee\x80\x80", "\xf0\x90\x80\x80",
                         "\xf4\x8f\xbf\xbf"})
    CHECK_MESSAGE(is_valid_utf8(ok), ok);
  CHECK(is_valid_utf8(std::string("a\0b", 3)));
  // Truncated, stray continuation, overlong, surrogate, above U+10FFFF, bad continuation.
  for (const char* bad : {"\xc3", "\xe2\x82", "\x80", "\xc0\xaf", "\xe0\x80\xaf",
                          "\xf0\x8f\xbf\xbf", "\xed\xa0\x80", "\xf4\x90\x80\x80",
                          "\xf8\x88\x80\x80\x80", "\xe2\x28\xa1"})
    CHECK_FALSE_MESSAGE(is_valid_utf8(bad), bad);
  TempDir tmp;
  std::vector<std::string> bad_row = row_cells(1);
  bad_row[7] = "walker\xff";  // pedestrian.model
  const std::string path = tmp.write("data.csv", header_line() + join(row_cells(0)) + join(bad_row));
  const PoseTable t = read_pose_csv(path);  // bytes are kept as they are
  CHECK(t.model.values[1] == "walker\xff");
  CHECK_THROWS_WITH_AS(check_utf8(t),
                       (path + ", line 3, column 'pedestrian.model': value 'walker\\xff' is not "
                               "valid UTF-8")
                           .c_str(),
                       CsvParseError);
  CsvReadOptions numbers_only;
  numbers_only.columns = {"frame.idx"};
  numbers_only.check_duplicates = false;
  check_utf8(read_pose_csv(path, numbers_only));  // no string column was read: nothing to check
}

namespace {
// Over 13 MB (three threads get a range each): ids first seen anywhere, blank lines, CRLF
// and LF lines mixed, rows that cross the 1 MB buffers and the ranges; `ending` is the end
// of the last row ("" leaves it without a line end).
std::string one_pass_file(const std::string& ending) {
  std::string text = header_line();
  std::mt19937 rng(59);
  for (int i = 1; text.size() < (std::size_t{13} << 20); ++i) {
    const std::string id = "clip-" + std::to_string(rng() % (i / 200 + 2));
    const bool crlf = rng() % 3 == 0;
    text += join(row_cells(i, id), crlf ? "\r\n" : "\n");
    if (rng() % 50 == 0) text += rng() % 2 ? "\n" : "\r\n";  // a blank line
  }
  return text + join(row_cells(1 << 20, "clip-last"), ending.c_str());
}

void check_same_columns(PoseTable& a, PoseTable& b) {
  REQUIRE(a.rows == b.rows);
  CHECK(a.line == b.line);
  CHECK(a.file_crc32 == b.file_crc32);
  CHECK(a.file_bytes == b.file_bytes);
  for (const std::string& name : a.columns_present) {
    INFO(name);
    const PoseColumn x = pose_column(a, name), y = pose_column(b, name);
    if (x.strings) {
      CHECK(x.strings->values == y.strings->values);  // first-seen order
      CHECK(x.strings->codes == y.strings->codes);
    } else if (x.ints) {
      CHECK(*x.ints == *y.ints);
    } else if (x.bools) {
      CHECK(*x.bools == *y.bools);
      CHECK(*x.valid == *y.valid);
    } else {
      CHECK(std::memcmp(x.floats->data(), y.floats->data(), x.floats->size() * 4) == 0);
    }
  }
}
}  // namespace

TEST_CASE("a deferred read indexes and parses in one pass: the two-pass table, any threads") {
  TempDir tmp;
  const std::vector<std::string> poses = {"frame.pedestrian.pose.world",
                                          "frame.pedestrian.pose.relative"};
  for (const char* ending : {"\n", "\r\n", ""}) {
    const std::string p = tmp.write("one.csv", one_pass_file(ending));
    PoseTable full = read_pose_csv(p);  // two passes, nothing deferred
    for (int threads : {1, 2, 3}) {
      INFO("threads " << threads << ", ending '" << ending << "'");
      CsvReadOptions o;
      o.threads = threads;
      o.deferred = poses;
      PoseTable t = read_pose_csv(p, o);
      CHECK(t.columns_present.size() == kPoseCsvColumnCount - 2);
      check_same_columns(t, full);
      // Each row's bytes (and where its first deferred cell begins): the deferred cells
      // read from them are the up-front values.
      REQUIRE(t.row_skip.size() == t.rows);
      CHECK(std::count(t.row_skip.begin(), t.row_skip.end(), PoseTable::kUnknownSkip) == 0);
      const DeferredCells cells(t, o);
      std::vector<std::size_t> rows(t.rows);
      for (std::size_t r = 0; r < t.rows; ++r) rows[r] = r;
      std::vector<float> out(t.rows * cells.floats_per_row());
      std::vector<char> buf;
      cells.read(rows.data(), rows.size(), out.data(), buf);
      const std::size_t k = cells.floats_per_row();
      bool same = true;
      for (std::size_t r = 0; r < t.rows && same; ++r)
        same = std::memcmp(&out[r * k + static_cast<std::size_t>(cells.offset_of(17))],
                           &full.pose_world[r * 156], 156 * 4) == 0 &&
               std::memcmp(&out[r * k + static_cast<std::size_t>(cells.offset_of(19))],
                           &full.pose_relative[r * 156], 156 * 4) == 0;
      CHECK(same);
    }
  }
}

TEST_CASE("a bad row read in one pass is named as the two-pass read names it") {
  TempDir tmp;
  std::string text = one_pass_file("\n");
  CsvReadOptions o;
  o.deferred = {"frame.pedestrian.pose.world"};
  // A bad integer in a row of each third of the file, in the rows that cross the threads'
  // ranges (the third and the half of the file), and on the last line.
  const std::size_t third = (text.size() + 2) / 3, half = (text.size() + 1) / 2;
  for (const std::size_t at : {text.size() / 20, third, half, 2 * third, text.size() / 2 + 7777,
                               text.size() - 1}) {
    std::string bad = text;
    const std::size_t row = bad.rfind("\nclip-", at);
    const std::size_t cell = bad.find(",1600,", row);
    bad.replace(cell, 6, ",16x0,");
    const std::string p = tmp.write("bad.csv", bad);
    const std::string expected = error_of(p);
    CHECK(expected.find("column 'camera.width'") != std::string::npos);
    for (int threads : {1, 2, 3}) {
      o.threads = threads;
      CHECK(error_of(p, o) == expected);
    }
  }
  // Cut in the middle of the last row: the two-pass read's "no line end" error.
  const std::string p = tmp.write("cut.csv", text.substr(0, text.size() - 300));
  o.threads = 3;
  CHECK(error_of(p, o) == error_of(p));
  CHECK(error_of(p, o).find("(the last line has no line end") != std::string::npos);
}
