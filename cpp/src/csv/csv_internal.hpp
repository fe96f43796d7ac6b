// Internals shared by the CSV reader and writer (cpp/src/csv/): the hot-loop scanners.
// The scanners follow fast_float's discipline: they never throw or allocate, and return
// where they stopped plus whether the cell was well-formed. Explaining a failure (what was
// expected, what was found) is the cold path's job (explain.cpp), which re-reads the
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

#include "bsp/csv/columns.hpp"
#include "bsp/csv/csv.hpp"

namespace bsp::csv_detail {

inline constexpr int kCrossingColumn = 20;
inline constexpr int kKeyColumns[4] = {0, 2, 6, 11};  // id, camera.idx, pedestrian.idx, frame.idx

// The values an integer column accepts: indices are never negative, frame indices and
// picture sizes stay below what any recording could have (a larger value is hostile or
// corrupt input and would otherwise size an allocation or index the media plan).
struct IntRange {
  std::int64_t lo, hi;
  const char* what;  // for error messages
};
inline constexpr std::int64_t kMaxFrameIdx = 10'000'000;  // over 90 hours at 30 fps
inline constexpr std::int64_t kMaxPictureSide = 16384;
inline constexpr IntRange int_range(int col) {
  switch (col) {
    case 4: case 5: return {1, kMaxPictureSide, "a picture size in pixels"};
    case 11: return {0, kMaxFrameIdx, "a frame index"};
    case 14: return {0, std::int64_t{1} << 40, "a world frame number"};
    default: return {0, std::numeric_limits<std::int32_t>::max(), "an index"};
  }
}

// "a, b, ..., <alias>": the names a column selection accepts, for error messages.
std::string allowed_columns();

// "text" shortened and escaped for an error message.
std::string snippet(std::string_view text, std::size_t max_chars = 40);

// Explains why a row failed. `failed_cell` is the header cell where the hot loop stopped;
// `header_cols` maps each header cell to a column index or -1. Returns "column 'x': ...".
std::string explain_row(std::string_view row, std::size_t failed_cell,
                        const std::vector<std::string>& header,
                        const std::vector<int>& header_cols);

// data.csv, read with pread(2) into buffers rather than memory-mapped: a file truncated by
// another process while it is read then gives a short read (FileChanged) instead of a
// SIGBUS, so no signal handler and no jump out of C++ frames is needed; and the resident set
// stays at the buffers' size, however large the file.
struct FileChanged {};  // the file shrank or was modified while it was being read

class InputFile {
 public:
  explicit InputFile(const std::string& path);  // CsvParseError if it cannot be opened
  ~InputFile();
  InputFile(const InputFile&) = delete;
  InputFile& operator=(const InputFile&) = delete;
  const std::string& path() const { return path_; }
  std::size_t size() const { return size_; }  // when opened
  std::int64_t mtime_ns() const { return mtime_ns_; }  // when opened
  // Reads bytes [offset, offset + n) into `out`; FileChanged when the file now ends earlier.
  void read(std::size_t offset, std::size_t n, char* out) const;
  // FileChanged when the file's size or modification time differs from when it was opened.
  void check_unchanged() const;

 private:
  std::string path_;
  int fd_ = -1;
  std::size_t size_ = 0;
  std::int64_t mtime_ns_ = 0;
};

// Bytes read (and scanned while in cache) at a time by each thread.
inline constexpr std::size_t kScanBytes = std::size_t{1} << 20;

// The file's lines: the header and the non-blank data lines (offsets exclude "\r\n"), and
// the CRC-32 of the whole file, computed while the line ends were searched.
struct Lines {
  std::string header;
  std::vector<std::size_t> begin, end;
  std::vector<std::int64_t> number;  // 1-based line numbers
  bool last_unterminated = false;    // the file does not end with a line end
  std::uint32_t crc32 = 0;
};

// Parses every data line into the columns selected by `cols` (header cell -> column index
// or -1 to skip), in parallel; throws CsvParseError naming the first bad row.
void parse_rows(const InputFile& file, const Lines& lines, const std::vector<std::string>& header,
                const std::vector<int>& cols, PoseTable& t, int threads,
                std::atomic<std::uint64_t>* rows_done = nullptr);

// One read of the whole file instead of two (the line index, then the rows): each thread
// scans a byte range for its newlines and CRC-32 and parses the rows that end in it from
// the same buffers into a table of its own; the tables are then joined in file order into
// t's columns (`cols` as for parse_rows), with t.line, t.row_begin/row_end and
// t.file_crc32. Used when the table defers the big columns (csv.hpp): what it holds is then
// small, and the copy cheap. Returns false, leaving t incomplete, when a row is bad: the
// caller then reads the file with index_lines + parse_rows, which name the first bad row.
bool scan_parse_rows(const InputFile& file, const std::vector<int>& cols, PoseTable& t,
                     int threads, std::atomic<std::uint64_t>* rows_done = nullptr);

// ------------------------------------------------------------------------ scanners
inline const char* skip_spaces(const char* p, const char* end) {
  while (p < end && *p == ' ') ++p;
  return p;
}

// ------------------------------------------------------------------------ numbers
// Python's repr of a float is almost always "-?d+.d+" with at most 17 significant digits.
// That shape is scanned 8 bytes at a time (branches depend on digit counts, not on every
// digit) into an integer w and a count kf of fraction digits, and rounded to float32
// through one double division (below), bit-identical to fast_float::from_chars, which
// handles everything else: exponents, nan/inf, >19 digits, the last bytes of a line, and
// the rare decimal that lies too close to a float rounding boundary. Only fast_float's
// documented from_chars is used.
[[gnu::noinline, gnu::cold]] inline bool parse_float_generic(const char*& p, const char* end,
                                                            float& out) {
  const auto r = fast_float::from_chars(p, end, out);
  if (r.ec != std::errc()) return false;
  p = r.ptr;
  return true;
}

#if defined(__BYTE_ORDER__) && __BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__
#define BSP_CSV_NUMBER_FAST_PATH 1
inline std::uint64_t load8(const char* p) {
  std::uint64_t v;
  std::memcpy(&v, p, 8);
  return v;
}

// Index of the first non-digit byte of 8 little-endian chars (8 if all are digits).
inline unsigned digit_run(std::uint64_t v) {
  const std::uint64_t hi = 0xF0F0F0F0F0F0F0F0ull, zeros = 0x3030303030303030ull;
  const std::uint64_t z = ((v & hi) ^ zeros) | (((v + 0x0606060606060606ull) & hi) ^ zeros);
  return z ? static_cast<unsigned>(__builtin_ctzll(z)) >> 3 : 8u;
}

// Value of 8 ASCII digits, little-endian (the SWAR step of simdjson and fast_float).
inline std::uint32_t eight_digits(std::uint64_t v) {
  v -= 0x3030303030303030ull;
  v = v * 10 + (v >> 8);
  v = ((v & 0x000000FF000000FFull) * 0x000F424000000064ull +
       ((v >> 16) & 0x000000FF000000FFull) * 0x0000271000000001ull) >> 32;
  return static_cast<std::uint32_t>(v);
}

// Value of the first k (1..8) digits of v: shift them to the top, pad with '0's.
inline std::uint64_t digits_value(std::uint64_t v, unsigned k) {
  const unsigned shift = (8 - k) * 8;
  if (shift) v = (v << shift) | (0x3030303030303030ull >> (64 - shift));
  return eight_digits(v);
}

inline constexpr std::uint64_t kPow10[9] = {1, 10, 100, 1000, 10000, 100000, 1000000,
                                            10000000, 100000000};
// 10^0 .. 10^19, each exact in a double (every power up to 10^22 is).
inline constexpr double kPow10Exact[20] = {1e0,  1e1,  1e2,  1e3,  1e4,  1e5,  1e6,
                                           1e7,  1e8,  1e9,  1e10, 1e11, 1e12, 1e13,
                                           1e14, 1e15, 1e16, 1e17, 1e18, 1e19};

// Appends the fraction digits at f (up to 3 chunks of 8) to w; returns how many there were,
// or 0 when the fast path cannot take them (no digit, or more than 19 digits in all).
inline unsigned append_fraction(const char* f, unsigned int_digits, std::uint64_t& w) {
  unsigned total = 0;
  for (int chunk = 0; chunk < 3; ++chunk) {
    const std::uint64_t v = load8(f + total);
    const unsigned k = digit_run(v);
    if (int_digits + total + k > 19) return 0;  // w would overflow
    if (k < 8) {  // the last chunk; k = 0 too, without a branch (two shifts of 32)
      static constexpr std::uint64_t kPad[8] = {  // '0' in the bytes the shift empties
          0x3030303030303030ull, 0x30303030303030ull, 0x303030303030ull, 0x3030303030ull,
          0x30303030ull, 0x303030ull, 0x3030ull, 0x30ull};
      const unsigned half = 4 * (8 - k);
      w = w * kPow10[k] + eight_digits(((v << half) << half) | kPad[k]);
      return total + k;
    }
    w = w * 100000000ull + eight_digits(v);
    total += 8;
  }
  return 0;
}
#else
#define BSP_CSV_NUMBER_FAST_PATH 0
#endif

[[gnu::always_inline]] inline bool parse_float(const char*& p, const char* end, float& out) {
#if BSP_CSV_NUMBER_FAST_PATH
  if (end - p < 48) return parse_float_generic(p, end, out);  // loads read < 48 bytes ahead
  const char* s = p + (*p == '-');
  const std::uint64_t head = load8(s);
  const unsigned ki = digit_run(head);  // integer digits
  if (ki == 0 || ki == 8 || s[ki] != '.') return parse_float_generic(p, end, out);
  std::uint64_t w = digits_value(head, ki);
  const unsigned kf = append_fraction(s + ki + 1, ki, w);  // 1..18
  const char* stop = s + ki + 1 + kf;
  if (kf == 0 || *stop == 'e' || *stop == 'E') return parse_float_generic(p, end, out);
  // x = w / 10^kf. w < 10^19 < 2^64 and 10^kf is exact, so d lies within a relative 2^-52
  // of x (two correctly rounded steps). If d * (1 - 2^-50) and d * (1 + 2^-50), which
  // bracket x even after their own rounding, round to the same float, x rounds to it too
  // (rounding is monotone): the correctly rounded float, as from_chars gives. Otherwise x
  // lies within ~2^-50 of a float rounding boundary (~3 decimals in 10^8): from_chars.
  // 1e-19 <= x < 1e18 (or 0): no subnormal float, no overflow.
  const double d = static_cast<double>(w) / kPow10Exact[kf];
  const float v = static_cast<float>(d * (1 + 0x1p-50));
  if (static_cast<float>(d * (1 - 0x1p-50)) != v) return parse_float_generic(p, end, out);
  // The sign without a branch: a random sign mispredicts half the time, ~1/6 of the time
  // of a number (callgrind --branch-sim on the benchmark's pose cells). v >= 0 here, so -v
  // is v with its sign bit set, bit for bit (-0.0 too).
  std::uint32_t bits;
  std::memcpy(&bits, &v, sizeof bits);
  bits |= static_cast<std::uint32_t>(*p == '-') << 31;
  std::memcpy(&out, &bits, sizeof bits);
  p = stop;
  return true;
#else
  return parse_float_generic(p, end, out);
#endif
}

// "[a, b, ...]" with exactly n numbers (bare nan/inf allowed) -> out[0..n).
inline bool scan_numbers(const char*& p, const char* end, float* out, int n) {
  if (p == end || *p != '[') return false;
  ++p;
  for (int i = 0; i < n; ++i) {
    if (p < end && *p == ' ') p = skip_spaces(p + 1, end);
    if (!parse_float(p, end, out[i])) return false;
    const char sep = i + 1 < n ? ',' : ']';
    if (p < end && *p == sep) {  // as Python writes lists: no space before the separator
      ++p;
      continue;
    }
    p = skip_spaces(p, end);
    if (p == end || *p != sep) return false;
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

// A list cell. Every list here has at least two numbers, hence a comma, so pandas always
// quoted it; an unquoted list would be several CSV cells and is rejected. An empty cell (or
// "") reads as NaNs: missing data.
inline bool scan_list_cell(const char*& p, const char* end, const CsvColumnSpec& s, float* out) {
  if (p == end || *p == ',' || (end - p >= 2 && p[0] == '"' && p[1] == '"')) {
    p += (p < end && *p == '"') ? 2 : 0;
    std::fill(out, out + s.numbers(), std::numeric_limits<float>::quiet_NaN());
    return true;
  }
  if (*p != '"') return false;
  const char* q = p + 1;
  const bool ok = s.outer ? scan_nested(q, end, out, s.outer, s.inner)
                          : scan_numbers(q, end, out, s.inner);
  if (!ok || q == end || *q != '"') return false;
  p = q + 1;
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
