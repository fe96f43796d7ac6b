// data.csv reader: pread in parallel byte ranges (line index and CRC-32 in one scan), header,
// then parallel row parsing straight into the preallocated columns of a PoseTable
// (docs/dataset-format.md, "2. data.csv").
#include <fcntl.h>
#include <libdeflate.h>
#include <sys/stat.h>
#include <unistd.h>
#include <zlib.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <memory>
#include <mutex>
#include <numeric>
#include <stdexcept>
#include <tuple>

#include "bsp/common/errors.hpp"
#include "bsp/common/parallel.hpp"
#include "csv_internal.hpp"

namespace bsp {

namespace csv_detail {

InputFile::InputFile(const std::string& path) : path_(path) {
  fd_ = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd_ < 0) throw CsvParseError(path + ": cannot open: " + std::strerror(errno));
  struct stat st {};
  if (::fstat(fd_, &st) != 0) {
    const int err = errno;
    ::close(fd_);
    throw CsvParseError(path + ": cannot stat: " + std::strerror(err));
  }
  size_ = static_cast<std::size_t>(st.st_size);
  mtime_ns_ = std::int64_t{st.st_mtim.tv_sec} * 1000000000 + st.st_mtim.tv_nsec;
  ::posix_fadvise(fd_, 0, 0, POSIX_FADV_SEQUENTIAL);
}

InputFile::~InputFile() { ::close(fd_); }

void InputFile::read(std::size_t offset, std::size_t n, char* out) const {
  while (n) {
    const ssize_t got = ::pread(fd_, out, n, static_cast<off_t>(offset));
    if (got < 0 && errno == EINTR) continue;
    if (got < 0) throw CsvParseError(path_ + ": cannot read: " + std::strerror(errno));
    if (got == 0) throw FileChanged();  // the file ends before the size it had when opened
    out += got, offset += static_cast<std::size_t>(got), n -= static_cast<std::size_t>(got);
  }
}

void InputFile::check_unchanged() const {
  struct stat st {};
  if (::fstat(fd_, &st) != 0 || static_cast<std::size_t>(st.st_size) != size_ ||
      std::int64_t{st.st_mtim.tv_sec} * 1000000000 + st.st_mtim.tv_nsec != mtime_ns_)
    throw FileChanged();
}

}  // namespace csv_detail

namespace {
using namespace csv_detail;

// Offsets of every '\n', found in parallel over byte ranges (memchr-bound), each flagged
// when a '\r' precedes it, and the CRC-32 of the bytes: one read of the file.
struct Newlines {
  std::vector<std::size_t> pos;
  std::vector<std::uint8_t> cr;
  std::uint32_t crc32 = 0;
  char last = 0;  // the file's last byte
};

Newlines find_newlines(const InputFile& file, int threads) {
  const std::size_t size = file.size();
  std::mutex mutex;
  struct Part {
    std::size_t lo, hi;
    Newlines found;
  };
  std::vector<Part> parts;
  parallel_for(size, std::size_t{1} << 22, [&](std::size_t lo, std::size_t hi) {
    Newlines found;
    std::unique_ptr<char[]> buf(new char[kScanBytes]);
    char before = 0;  // the byte before buf[0]
    if (lo > 0) file.read(lo - 1, 1, &before);
    std::uint32_t crc = 0;
    for (std::size_t a = lo; a < hi; a += kScanBytes) {
      const std::size_t n = std::min(hi, a + kScanBytes) - a;
      file.read(a, n, buf.get());
      crc = libdeflate_crc32(crc, buf.get(), n);
      const char* const data = buf.get();
      for (const char* p = data; p < data + n; ++p) {
        p = static_cast<const char*>(std::memchr(p, '\n', static_cast<std::size_t>(data + n - p)));
        if (!p) break;
        found.pos.push_back(a + static_cast<std::size_t>(p - data));
        found.cr.push_back((p > data ? p[-1] : before) == '\r');
      }
      before = data[n - 1];
    }
    found.crc32 = crc;
    found.last = before;
    std::lock_guard<std::mutex> lock(mutex);
    parts.push_back({lo, hi, std::move(found)});
  }, threads);
  std::sort(parts.begin(), parts.end(), [](const Part& a, const Part& b) { return a.lo < b.lo; });
  Newlines all;
  for (std::size_t k = 0; k < parts.size(); ++k) {
    const Part& part = parts[k];
    all.pos.insert(all.pos.end(), part.found.pos.begin(), part.found.pos.end());
    all.cr.insert(all.cr.end(), part.found.cr.begin(), part.found.cr.end());
    // zlib joins the ranges' CRCs (libdeflate computes the same CRC-32, faster).
    all.crc32 = k == 0 ? part.found.crc32
                       : static_cast<std::uint32_t>(crc32_combine(
                             all.crc32, part.found.crc32, static_cast<z_off_t>(part.hi - part.lo)));
    all.last = part.found.last;
  }
  return all;
}

// Splits the file into the header and the non-blank data lines ('\r\n' or '\n').
Lines index_lines(const InputFile& file, int threads) {
  const std::size_t size = file.size();
  const Newlines nl = find_newlines(file, threads);
  Lines lines;
  lines.crc32 = nl.crc32;
  lines.last_unterminated = nl.pos.empty() || nl.pos.back() + 1 != size;
  const std::size_t count = nl.pos.size() + (lines.last_unterminated ? 1 : 0);
  lines.begin.reserve(count);
  lines.end.reserve(count);
  lines.number.reserve(count);
  std::size_t start = 0;
  for (std::size_t k = 0; k < count; ++k) {
    std::size_t stop = k < nl.pos.size() ? nl.pos[k] : size;
    const std::size_t next = stop + 1;
    const bool cr = k < nl.pos.size() ? nl.cr[k] != 0 : (stop > start && nl.last == '\r');
    if (cr && stop > start) --stop;
    if (k == 0) {
      lines.header.resize(stop - start);
      file.read(start, stop - start, lines.header.data());
    } else if (stop > start) {  // blank lines are skipped, as pandas does
      lines.begin.push_back(start);
      lines.end.push_back(stop);
      lines.number.push_back(static_cast<std::int64_t>(k + 1));
    }
    start = next;
  }
  return lines;
}

[[noreturn]] void header_error(const std::string& path, const std::string& msg) {
  throw CsvParseError(path + ", line 1 (header): " + msg);
}

// Header cell names (quotes removed, UTF-8 BOM dropped).
std::vector<std::string> split_header(std::string_view h, const std::string& path) {
  if (h.substr(0, 3) == "\xEF\xBB\xBF") h.remove_prefix(3);
  std::vector<std::string> names;
  const char* p = h.data();
  const char* end = p + h.size();
  for (;;) {
    std::string_view raw;
    bool escaped = false;
    if (!scan_string_cell(p, end, raw, escaped))
      header_error(path, "unterminated quote in column name " + snippet(std::string_view(
                             p, static_cast<std::size_t>(end - p))));
    names.push_back(escaped ? unescape_quotes(raw) : std::string(raw));
    if (p == end) return names;
    if (*p != ',')
      header_error(path, "expected ',' after column name " + snippet(names.back()) +
                             ", found " + snippet(std::string_view(
                                 p, static_cast<std::size_t>(end - p))));
    ++p;
  }
}

// Which columns to parse: the requested ones, plus the key columns for the duplicate check.
std::vector<bool> wanted_columns(const CsvReadOptions& opt) {
  std::vector<bool> wanted(kPoseCsvColumnCount, opt.columns.empty());
  for (const std::string& name : opt.columns) {
    const int c = pose_csv_column_index(name);
    if (c < 0) {
      throw std::invalid_argument("read_pose_csv: unknown column '" + name + "'; allowed: " +
                                  allowed_columns());
    }
    wanted[static_cast<std::size_t>(c)] = true;
  }
  if (opt.check_duplicates)
    for (int c : kKeyColumns) wanted[static_cast<std::size_t>(c)] = true;
  for (const std::string& name : opt.deferred) {
    const int c = pose_csv_column_index(name);
    if (c < 0 || kPoseCsvSpecs[c].kind != CsvKind::floats || !wanted[static_cast<std::size_t>(c)])
      throw std::invalid_argument("read_pose_csv: cannot defer column '" + name +
                                  "': only selected float list columns can be");
  }
  return wanted;
}

// The deferred columns and the header cell of each, in header order; a missing one is
// refused by map_header like any required column.
void defer_columns(const CsvReadOptions& opt, const std::vector<std::string>& names,
                   std::vector<int>& cols, PoseTable& t) {
  for (std::size_t k = 0; k < names.size(); ++k) {
    const int c = cols[k];
    if (c < 0) continue;
    for (const std::string& name : opt.deferred)
      if (pose_csv_column_index(name) == c) {
        t.deferred_columns.push_back(c);
        t.deferred_cells.push_back(static_cast<int>(k));
        cols[k] = -1;  // skipped by the row parser: DeferredCells reads it
      }
  }
  t.header_cells = names.size();
  auto& present = t.columns_present;  // only what the table holds
  const auto& deferred = t.deferred_columns;
  present.erase(std::remove_if(present.begin(), present.end(), [&](const std::string& name) {
    const int c = pose_csv_column_index(name);
    return std::find(deferred.begin(), deferred.end(), c) != deferred.end();
  }), present.end());
}

// Maps header cells to wanted column indices (-1 = skip); every wanted column must appear.
std::vector<int> map_header(const std::vector<std::string>& names, const std::vector<bool>& wanted,
                            const CsvReadOptions& opt, PoseTable& t) {
  std::vector<int> cols(names.size(), -1);
  std::vector<int> seen(kPoseCsvColumnCount, -1);
  for (std::size_t k = 0; k < names.size(); ++k) {
    const int c = pose_csv_column_index(names[k]);
    if (c < 0) continue;  // unknown extra columns are ignored
    if (seen[static_cast<std::size_t>(c)] >= 0)
      header_error(t.path, "column '" + names[k] + "' appears twice (as '" +
                               names[static_cast<std::size_t>(seen[c])] + "' in cell " +
                               std::to_string(seen[c] + 1) + " and in cell " +
                               std::to_string(k + 1) + ")");
    seen[static_cast<std::size_t>(c)] = static_cast<int>(k);
    if (wanted[static_cast<std::size_t>(c)]) cols[k] = c;
  }
  for (std::size_t c = 0; c < kPoseCsvColumnCount; ++c) {
    if (!wanted[c]) continue;
    if (seen[c] < 0) {
      const bool key_only = !opt.columns.empty() &&
                            std::find(std::begin(kKeyColumns), std::end(kKeyColumns),
                                      static_cast<int>(c)) != std::end(kKeyColumns);
      header_error(t.path, "missing required column '" + std::string(kPoseCsvColumns[c]) + "'" +
                               (c == kCrossingColumn ? std::string(" (or '") + kCrossingAlias + "')"
                                                     : std::string()) +
                               (key_only ? " (needed by the duplicate check; disable it "
                                           "with check_duplicates=false)" : ""));
    }
    t.columns_present.emplace_back(kPoseCsvColumns[c]);
    if (c == static_cast<std::size_t>(kCrossingColumn))
      t.crossing_column = names[static_cast<std::size_t>(seen[c])];
  }
  return cols;
}

// The first duplicate (id, camera.idx, pedestrian.idx, frame.idx) in file order is an error.
void check_duplicates(const PoseTable& t) {
  std::vector<std::uint32_t> order(t.rows);
  std::iota(order.begin(), order.end(), 0u);
  const auto key = [&](std::uint32_t r) {
    return std::make_tuple(t.id.codes[r], t.camera_idx[r], t.pedestrian_idx[r], t.frame_idx[r],
                           r);
  };
  std::sort(order.begin(), order.end(), [&](auto a, auto b) { return key(a) < key(b); });
  std::size_t best = t.rows;  // index into order of the earliest second occurrence
  for (std::size_t i = 1; i < order.size(); ++i) {
    const auto a = key(order[i - 1]), b = key(order[i]);
    const bool same = std::get<0>(a) == std::get<0>(b) && std::get<1>(a) == std::get<1>(b) &&
                      std::get<2>(a) == std::get<2>(b) && std::get<3>(a) == std::get<3>(b);
    if (same && (best == t.rows || order[i] < order[best])) best = i;
  }
  if (best == t.rows) return;
  std::size_t first = best;  // the group's first row precedes `best` in sorted order
  while (first > 0 && t.id.codes[order[first - 1]] == t.id.codes[order[best]] &&
         t.camera_idx[order[first - 1]] == t.camera_idx[order[best]] &&
         t.pedestrian_idx[order[first - 1]] == t.pedestrian_idx[order[best]] &&
         t.frame_idx[order[first - 1]] == t.frame_idx[order[best]])
    --first;
  const std::uint32_t r = order[best];
  throw CsvParseError(
      t.path + ", line " + std::to_string(t.line[r]) +
      ", columns (id, camera.idx, pedestrian.idx, frame.idx): duplicate key (" +
      snippet(t.id.values[static_cast<std::size_t>(t.id.codes[r])], 80) + ", " +
      std::to_string(t.camera_idx[r]) + ", " + std::to_string(t.pedestrian_idx[r]) + ", " +
      std::to_string(t.frame_idx[r]) + "): expected each key once, found it on line " +
      std::to_string(t.line[order[first]]) + " and line " + std::to_string(t.line[r]));
}

void parse_file(const InputFile& file, const CsvReadOptions& opt,
                const std::vector<bool>& wanted, int threads, PoseTable& t);

}  // namespace

PoseTable read_pose_csv(const std::string& path, const CsvReadOptions& opt) {
  const std::vector<bool> wanted = wanted_columns(opt);
  const int threads = opt.threads > 0 ? opt.threads : num_threads();
  const InputFile file(path);
  if (file.size() == 0) throw CsvParseError(path + ", line 1 (header): empty file, no header");
  PoseTable t;
  try {
    // Another process may truncate or rewrite the file while it is read: a read past its
    // new end, or a size or modification time that changed by the end, is this error.
    parse_file(file, opt, wanted, threads, t);
    file.check_unchanged();
    return t;
  } catch (const FileChanged&) {
  }
  throw CsvParseError(path + ": the file changed while it was being read (truncated by "
                      "another process?); nothing was parsed");
}

namespace {
// A '\r' left inside the first line means CR-only line ends (classic Mac): the whole file
// would read as a header and no rows. Refused rather than converted to nothing.
void refuse_cr_only(const std::string& header, const std::string& path) {
  if (const std::size_t cr = header.find('\r'); cr != std::string_view::npos)
    throw CsvParseError(path + ", line 1 (header): found a carriage return without a line "
                        "feed at byte " + std::to_string(cr) + ": CR-only line ends are not "
                        "supported (expected '\\n' or '\\r\\n' line ends)");
}

// The first line without its line end (all of the file when it holds no '\n').
std::string read_header(const InputFile& file) {
  std::string header;
  for (std::size_t at = 0; at < file.size();) {
    const std::size_t n = std::min<std::size_t>(std::size_t{1} << 16, file.size() - at);
    header.resize(at + n);
    file.read(at, n, header.data() + at);
    const std::size_t nl = header.find('\n', at);
    at += n;
    if (nl != std::string::npos) {
      header.resize(nl);
      break;
    }
  }
  if (!header.empty() && header.back() == '\r') header.pop_back();
  return header;
}

// With deferred columns the rows are parsed in the pass that indexes the file (csv_detail::
// scan_parse_rows): one read of it instead of two. False when a row is bad: t is then read
// again the two-pass way, whose error names it.
bool parse_one_pass(const InputFile& file, const CsvReadOptions& opt,
                    const std::vector<bool>& wanted, int threads, PoseTable& t) {
  const std::string header = read_header(file);
  refuse_cr_only(header, t.path);
  const std::vector<std::string> names = split_header(header, t.path);
  std::vector<int> cols = map_header(names, wanted, opt, t);
  defer_columns(opt, names, cols, t);
  t.file_bytes = file.size();
  t.file_mtime_ns = file.mtime_ns();
  if (!csv_detail::scan_parse_rows(file, cols, t, threads, opt.rows_done)) return false;
  if (opt.rows_total) *opt.rows_total = t.rows;
  return true;
}

void parse_file(const InputFile& file, const CsvReadOptions& opt,
                const std::vector<bool>& wanted, int threads, PoseTable& t) {
  const std::string& path = file.path();
  t.path = path;
  if (!opt.deferred.empty()) {
    if (parse_one_pass(file, opt, wanted, threads, t)) {
      if (opt.check_duplicates) check_duplicates(t);
      return;
    }
    t = PoseTable();
    t.path = path;
  }
  const csv_detail::Lines lines = index_lines(file, threads);
  t.file_bytes = file.size();
  t.file_crc32 = lines.crc32;
  refuse_cr_only(lines.header, path);
  const std::vector<std::string> names = split_header(lines.header, path);
  std::vector<int> cols = map_header(names, wanted, opt, t);
  t.rows = lines.begin.size();
  t.line = lines.number;
  if (!opt.deferred.empty()) {
    defer_columns(opt, names, cols, t);
    t.row_begin.assign(lines.begin.begin(), lines.begin.end());
    t.row_end.assign(lines.end.begin(), lines.end.end());
    t.file_mtime_ns = file.mtime_ns();
  }
  if (opt.rows_total) *opt.rows_total = t.rows;
  csv_detail::parse_rows(file, lines, names, cols, t, threads, opt.rows_done);
  if (opt.check_duplicates) check_duplicates(t);
}
}  // namespace

}  // namespace bsp
