// Internals shared by the csv_*.cpp files: the column schema and the hot-loop scanners.
// The scanners follow fast_float's discipline: they never throw or allocate, and return
// where they stopped plus whether the cell was well-formed. Explaining a failure (what was
// expected, what was found) is the cold path's job (csv_explain.cpp), which re-reads the
// offending cell slowly.
#pragma once
#include <fast_float/fast_float.h>

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <string>
#include <string_view>
#include <vector>

#include "bsp/csv.hpp"

namespace bsp::csv_detail {

enum class Kind : std::uint8_t { string, integer, floats, boolean };

struct ColumnSpec {
  const char* name;
  Kind kind;
  std::uint16_t outer;  // lists per cell for nested cells, 0 for a flat list
  std::uint16_t inner;  // numbers per (inner) list
  std::size_t numbers() const { return outer ? std::size_t{outer} * inner : inner; }
};

extern const ColumnSpec kSpecs[kPoseCsvColumnCount];
inline constexpr int kCrossingColumn = 20;
inline constexpr int kKeyColumns[4] = {0, 2, 6, 11};  // id, camera.idx, pedestrian.idx, frame.idx

// Index of a CSV column name in kPoseCsvColumns (the crossing alias maps to 20), or -1.
int column_index(std::string_view name);

// Where a column lives in a PoseTable; only the members of its kind are set.
struct ColumnRef {
  StringColumn* str = nullptr;
  std::vector<std::int64_t>* ints = nullptr;
  std::vector<float>* floats = nullptr;
  std::vector<std::uint8_t>* bools = nullptr;
  std::vector<std::uint8_t>* valid = nullptr;
};
ColumnRef column_ref(PoseTable& t, int col);

// "text" shortened and escaped for an error message.
std::string snippet(std::string_view text, std::size_t max_chars = 40);

// Explains why a row failed. `failed_col` is the header cell where the hot loop stopped;
// `header_cols` maps each header cell to a column index or -1. Returns "column 'x': ...".
std::string explain_row(std::string_view row, std::size_t failed_cell,
                        const std::vector<std::string>& header,
                        const std::vector<int>& header_cols);

// The file's lines: the header and the non-blank data lines (offsets exclude "\r\n").
struct Lines {
  std::string_view header;
  std::vector<std::size_t> begin, end;
  std::vector<std::int64_t> number;  // 1-based line numbers
  bool last_unterminated = false;    // the file does not end with a line end
};

// Parses every data line into the columns selected by `cols` (header cell -> column index
// or -1 to skip), in parallel; throws CsvParseError naming the first bad row.
void parse_rows(const char* data, const Lines& lines, const std::vector<std::string>& header,
                const std::vector<int>& cols, PoseTable& t, int threads);

// ------------------------------------------------------------------------ scanners
inline const char* skip_spaces(const char* p, const char* end) {
  while (p < end && *p == ' ') ++p;
  return p;
}

// "[a, b, ...]" with exactly n numbers (bare nan/inf allowed) -> out[0..n).
inline bool scan_numbers(const char*& p, const char* end, float* out, int n) {
  if (p == end || *p != '[') return false;
  ++p;
  for (int i = 0; i < n; ++i) {
    p = skip_spaces(p, end);
    const auto r = fast_float::from_chars(p, end, out[i]);
    if (r.ec != std::errc()) return false;
    p = skip_spaces(r.ptr, end);
    if (p == end || *p != (i + 1 < n ? ',' : ']')) return false;
    ++p;
  }
  return true;
}

// "[[...], [...], ...]" with exactly `outer` lists of `inner` numbers.
inline bool scan_nested(const char*& p, const char* end, float* out, int outer, int inner) {
  if (p == end || *p != '[') return false;
  ++p;
  for (int j = 0; j < outer; ++j) {
    p = skip_spaces(p, end);
    if (!scan_numbers(p, end, out + static_cast<std::ptrdiff_t>(j) * inner, inner)) return false;
    p = skip_spaces(p, end);
    if (p == end || *p != (j + 1 < outer ? ',' : ']')) return false;
    ++p;
  }
  return true;
}

// A list cell, quoted or not. An empty cell (or "") reads as NaNs: missing data.
inline bool scan_list_cell(const char*& p, const char* end, const ColumnSpec& s, float* out) {
  const bool quoted = p < end && *p == '"';
  const bool empty = quoted ? (p + 1 < end && p[1] == '"') : (p == end || *p == ',');
  if (empty) {
    p += quoted ? 2 : 0;
    std::fill(out, out + s.numbers(), std::numeric_limits<float>::quiet_NaN());
    return true;
  }
  const char* q = p + (quoted ? 1 : 0);
  const bool ok = s.outer ? scan_nested(q, end, out, s.outer, s.inner)
                          : scan_numbers(q, end, out, s.inner);
  if (!ok) return false;
  if (quoted) {
    if (q == end || *q != '"') return false;
    ++q;
  }
  p = q;
  return true;
}

// An integer; pandas writes "600.0" for an int column that held a NaN, so ".0" is allowed.
inline bool scan_int_cell(const char*& p, const char* end, std::int64_t* out) {
  const auto r = std::from_chars(p, end, *out);
  if (r.ec != std::errc()) return false;
  p = r.ptr;
  if (p < end && *p == '.') {
    ++p;
    while (p < end && *p == '0') ++p;
  }
  return true;
}

inline bool starts_with(const char* p, const char* end, const char* word, std::size_t n) {
  return static_cast<std::size_t>(end - p) >= n && std::memcmp(p, word, n) == 0;
}

// True/False as pandas writes them (also true/TRUE, and 1/0/1.0/0.0 from a float column);
// empty = missing.
inline bool scan_bool_cell(const char*& p, const char* end, std::uint8_t* v, std::uint8_t* ok) {
  *ok = 1;
  for (const char* w : {"True", "true", "TRUE", "1.0", "1"})
    if (starts_with(p, end, w, std::strlen(w))) {
      *v = 1;
      p += std::strlen(w);
      return true;
    }
  for (const char* w : {"False", "false", "FALSE", "0.0", "0"})
    if (starts_with(p, end, w, std::strlen(w))) {
      *v = 0;
      p += std::strlen(w);
      return true;
    }
  *v = 0;
  *ok = 0;
  return p == end || *p == ',';
}

// A string cell, quoted (with "" escapes) or not. `raw` is the text between the quotes;
// `escaped` tells whether it still holds "" pairs.
inline bool scan_string_cell(const char*& p, const char* end, std::string_view& raw,
                             bool& escaped) {
  escaped = false;
  if (p < end && *p == '"') {
    const char* s = p + 1;
    const char* q = s;
    for (;;) {
      q = static_cast<const char*>(std::memchr(q, '"', static_cast<std::size_t>(end - q)));
      if (!q) return false;
      if (q + 1 < end && q[1] == '"') {
        escaped = true;
        q += 2;
        continue;
      }
      break;
    }
    raw = std::string_view(s, static_cast<std::size_t>(q - s));
    p = q + 1;
    return true;
  }
  const char* c = static_cast<const char*>(std::memchr(p, ',', static_cast<std::size_t>(end - p)));
  if (!c) c = end;
  raw = std::string_view(p, static_cast<std::size_t>(c - p));
  p = c;
  return true;
}

inline std::string unescape_quotes(std::string_view raw) {
  std::string s;
  s.reserve(raw.size());
  for (std::size_t i = 0; i < raw.size(); ++i) {
    s += raw[i];
    if (raw[i] == '"' && i + 1 < raw.size() && raw[i + 1] == '"') ++i;
  }
  return s;
}

}  // namespace bsp::csv_detail
