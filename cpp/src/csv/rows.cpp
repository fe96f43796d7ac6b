// The reader's hot loop: blocks of rows parsed in parallel, each thread reading its rows a
// buffer at a time and writing straight into the preallocated columns. Strings are
// dictionary-encoded per block and the block dictionaries merged in file order afterwards,
// so codes (first-seen order) and every other value are identical for any thread count.
// With deferred columns (csv.hpp) the rows are parsed in the pass that finds the lines and
// the CRC-32 (scan_parse_rows), from the same buffers: one read of the file, not two.
#include <libdeflate.h>
#ifdef __GLIBC__
#include <malloc.h>
#endif
#include <zlib.h>

#include <algorithm>
#include <cstring>
#include <deque>
#include <memory>
#include <mutex>
#include <unordered_map>

#include "bsp/common/errors.hpp"
#include "bsp/common/parallel.hpp"
#include "csv_internal.hpp"

namespace bsp::csv_detail {
namespace {

enum class Action : std::uint8_t { skip, string, integer, floats, boolean };

// What to do with one header cell, and where its values go.
struct Target {
  Action action = Action::skip;
  const CsvColumnSpec* spec = nullptr;
  std::size_t numbers = 0;
  float* f = nullptr;
  std::int64_t* i = nullptr;
  std::uint8_t* b = nullptr;
  std::uint8_t* v = nullptr;
  std::int32_t* codes = nullptr;
  StringColumn* str = nullptr;
  int dict = -1;
  std::int64_t lo = 0, hi = 0;  // integer columns: the accepted range
};

// First-seen dictionary of one string column within one block of rows. It owns its values
// (`owned_`: the read buffer is reused), which outlive the merge.
class LocalDict {
 public:
  std::int32_t code(std::string_view raw, bool escaped) {
    if (last_code_ >= 0 && !escaped && raw == last_) return last_code_;  // runs of one clip
    std::string unescaped;
    if (escaped) raw = unescaped = unescape_quotes(raw);
    auto it = index_.find(raw);
    if (it == index_.end()) {
      const std::string_view value = owned_.emplace_back(raw);
      it = index_.emplace(value, static_cast<std::int32_t>(values_.size())).first;
      values_.push_back(value);
    }
    last_ = it->first;
    last_code_ = it->second;
    return last_code_;
  }
  const std::vector<std::string_view>& values() const { return values_; }

 private:
  std::unordered_map<std::string_view, std::int32_t> index_;
  std::vector<std::string_view> values_;
  std::deque<std::string> owned_;
  std::string_view last_;
  std::int32_t last_code_ = -1;
};

constexpr std::size_t kNoRow = static_cast<std::size_t>(-1);

struct Block {
  std::size_t lo = 0, hi = 0;
  std::vector<LocalDict> dicts;
  std::size_t failed_row = kNoRow, failed_cell = 0;
  std::string failed_text;  // the bad row, for the error message
};

inline bool parse_cell(const Target& t, std::size_t row, const char*& p, const char* end,
                       Block& b) {
  std::string_view raw;
  bool escaped = false;
  switch (t.action) {
    case Action::floats: return scan_list_cell(p, end, *t.spec, t.f + row * t.numbers);
    case Action::integer:
      return scan_int_cell(p, end, t.i + row) && t.i[row] >= t.lo && t.i[row] <= t.hi;
    case Action::boolean: return scan_bool_cell(p, end, t.b + row, t.v + row);
    case Action::string:
      if (!scan_string_cell(p, end, raw, escaped)) return false;
      t.codes[row] = b.dicts[static_cast<std::size_t>(t.dict)].code(raw, escaped);
      return true;
    case Action::skip: return scan_string_cell(p, end, raw, escaped);
  }
  return false;
}

// Parses one row's text [line, end) into row `row` of the targets' columns; on a bad cell
// records where in b and returns false. `skip` (when not null): where cell `mark` begins.
bool parse_line(const std::vector<Target>& targets, std::size_t row, const char* line,
                const char* end, Block& b, std::size_t mark = kNoRow,
                std::uint32_t* skip = nullptr) {
  const std::size_t n = targets.size();
  const char* p = line;
  for (std::size_t c = 0; c < n; ++c) {
    if (c == mark) *skip = static_cast<std::uint32_t>(std::min<std::ptrdiff_t>(
                       p - line, PoseTable::kUnknownSkip));
    const bool ok = parse_cell(targets[c], row, p, end, b) &&
                    (c + 1 < n ? (p < end && *p++ == ',') : p == end);
    if (!ok) {
      b.failed_row = row;
      b.failed_cell = c;
      b.failed_text.assign(line, end);
      return false;
    }
  }
  return true;
}

// Parses rows [b.lo, b.hi), reading them from the file about kScanBytes at a time (at least
// one whole row); stops at the first bad row and records where.
void parse_block(const InputFile& file, const Lines& lines, const std::vector<Target>& targets,
                 Block& b, std::atomic<std::uint64_t>* rows_done) {
  std::vector<char> buf;
  for (std::size_t first = b.lo; first < b.hi;) {
    const std::size_t from = lines.begin[first];
    std::size_t last = first + 1;  // rows [first, last) fit the buffer
    while (last < b.hi && lines.end[last] - from <= kScanBytes) ++last;
    const std::size_t bytes = lines.end[last - 1] - from;
    if (buf.size() < bytes) buf.resize(std::max(bytes, kScanBytes));
    file.read(from, bytes, buf.data());
    for (std::size_t row = first; row < last; ++row) {
      if (rows_done && (row - b.lo) % 256 == 255) *rows_done += 256;
      if (!parse_line(targets, row, buf.data() + (lines.begin[row] - from),
                      buf.data() + (lines.end[row] - from), b))
        return;
    }
    first = last;
  }
  if (rows_done) *rows_done += (b.hi - b.lo) % 256;  // the rows not yet counted above
}

// Sizes the selected columns and points one Target at each header cell.
std::vector<Target> make_targets(const std::vector<int>& cols, PoseTable& t, int& dicts) {
  std::vector<Target> targets(cols.size());
  dicts = 0;
  for (std::size_t k = 0; k < cols.size(); ++k) {
    if (cols[k] < 0) continue;
    Target& g = targets[k];
    const PoseColumn r = pose_column(t, static_cast<std::size_t>(cols[k]));
    g.spec = &kPoseCsvSpecs[cols[k]];
    g.numbers = g.spec->numbers();
    switch (g.spec->kind) {
      case CsvKind::floats:
        r.floats->resize(t.rows * g.numbers);
        g.action = Action::floats, g.f = r.floats->data();
        break;
      case CsvKind::integer:
        r.ints->resize(t.rows);
        g.action = Action::integer, g.i = r.ints->data();
        g.lo = int_range(cols[k]).lo, g.hi = int_range(cols[k]).hi;
        break;
      case CsvKind::boolean:
        r.bools->resize(t.rows);
        r.valid->resize(t.rows);
        g.action = Action::boolean, g.b = r.bools->data(), g.v = r.valid->data();
        break;
      case CsvKind::string:
        r.strings->codes.resize(t.rows);
        g.action = Action::string, g.codes = r.strings->codes.data(), g.str = r.strings;
        g.dict = dicts++;
        break;
    }
  }
  return targets;
}

// Global first-seen dictionaries from the block ones, in file order; codes remapped.
void merge_strings(const std::vector<std::unique_ptr<Block>>& blocks,
                   const std::vector<Target>& targets) {
  for (const Target& g : targets) {
    if (g.action != Action::string) continue;
    std::unordered_map<std::string_view, std::int32_t> global;
    for (const auto& b : blocks) {
      std::vector<std::int32_t> remap;
      for (std::string_view v : b->dicts[static_cast<std::size_t>(g.dict)].values()) {
        const auto [it, inserted] =
            global.emplace(v, static_cast<std::int32_t>(g.str->values.size()));
        if (inserted) g.str->values.emplace_back(v);
        remap.push_back(it->second);
      }
      for (std::size_t r = b->lo; r < b->hi; ++r)
        g.codes[r] = remap[static_cast<std::size_t>(g.codes[r])];
    }
  }
}

// ---------------------------------------------------------------- one pass (scan_parse_rows)

// Reserves t's selected columns for t.rows rows.
void reserve_rows(PoseTable& t, const std::vector<int>& cols) {
  for (const int c : cols) {
    if (c < 0) continue;
    const PoseColumn r = pose_column(t, static_cast<std::size_t>(c));
    if (r.floats) r.floats->reserve(t.rows * r.spec->numbers());
    if (r.ints) r.ints->reserve(t.rows);
    if (r.bools) r.bools->reserve(t.rows), r.valid->reserve(t.rows);
    if (r.strings) r.strings->codes.reserve(t.rows);
  }
}


// One byte range [lo, hi) of the file read once: its CRC-32, its newlines, and the rows of
// the lines that end in it, parsed into a table of its own as the buffers are read. The
// line ending at the range's first newline began in an earlier range; it is parsed once
// every range is scanned, into row 0 (kept free) with dictionaries of its own (`first`),
// so that the string codes stay in first-seen order.
struct Part {
  std::size_t lo = 0, hi = 0;
  std::uint32_t crc = 0;
  std::size_t newlines = 0;                          // '\n' bytes in [lo, hi)
  std::size_t first_nl = kNoRow, last_nl = kNoRow;   // where the first and last are
  PoseTable table;                                   // row 0, then the rows parsed here
  std::vector<std::uint64_t> begin, end;             // bytes of rows 1.. (row r at r - 1)
  std::vector<std::size_t> nl_index;                 // index of the '\n' ending each, here
  Block rows, first;                                 // dictionaries and failure
  bool has_first = false;                            // row 0 holds a line
  std::uint64_t first_begin = 0, first_end = 0;      // its bytes
  std::size_t mark = kNoRow;                         // the first deferred cell
  std::vector<std::uint32_t> skip;                   // where it begins in each row
  std::uint32_t first_skip = PoseTable::kUnknownSkip;
  bool stopped = false;                              // a bad row: the scan stopped there
  std::size_t parsed() const { return begin.size(); }
};

// The line [s, x) of `part` (x: its '\n'; `text` its bytes): its '\r' dropped, parsed into
// the next row of the part's table unless blank. False for a bad row.
bool take_line(Part& part, const std::vector<Target>& targets, std::size_t s, std::size_t x,
               const char* text) {
  const char* end = text + (x - s);
  if (end > text && end[-1] == '\r') --end;
  if (end == text) return true;  // blank lines are skipped, as pandas does
  const std::size_t row = part.parsed() + 1;
  part.begin.push_back(s);
  part.end.push_back(s + static_cast<std::size_t>(end - text));
  part.nl_index.push_back(part.newlines - 1);
  part.skip.push_back(PoseTable::kUnknownSkip);
  return parse_line(targets, row, text, end, part.rows, part.mark, &part.skip.back());
}

// The lines of one buffer (bytes [a, a + n) in buf, newlines at nl) that begin after the
// part's first newline; a line begun in an earlier buffer is read again whole (`spill`).
bool take_lines(const InputFile& file, Part& part, const std::vector<int>& cols,
                std::size_t a, const char* buf, const std::vector<std::size_t>& nl,
                std::vector<char>& spill) {
  int dicts = 0;
  part.table.rows = part.parsed() + 1 + nl.size();  // room for every line that ends here
  const std::vector<Target> targets = make_targets(cols, part.table, dicts);
  for (const std::size_t x : nl) {
    ++part.newlines;
    const std::size_t s = part.last_nl + 1;  // part.last_nl: the newline before x
    part.last_nl = x;
    if (part.first_nl == kNoRow) {
      part.first_nl = x;
      continue;
    }
    if (s < a) {
      spill.resize(x - s);
      file.read(s, x - s, spill.data());
    }
    if (!take_line(part, targets, s, x, s < a ? spill.data() : buf + (s - a))) return false;
  }
  return true;
}

// Scans and parses one range (see Part); stops at the first bad row.
void scan_part(const InputFile& file, const std::vector<int>& cols, int dicts, Part& part,
               std::atomic<std::uint64_t>* rows_done) {
  std::unique_ptr<char[]> buf(new char[kScanBytes]);
  std::vector<char> spill;
  std::vector<std::size_t> nl;
  bool reserved = false;
  part.rows.dicts.resize(static_cast<std::size_t>(dicts));
  part.first.dicts.resize(static_cast<std::size_t>(dicts));
  for (std::size_t a = part.lo; a < part.hi; a += kScanBytes) {
    const std::size_t n = std::min(part.hi, a + kScanBytes) - a;
    file.read(a, n, buf.get());
    part.crc = libdeflate_crc32(part.crc, buf.get(), n);
    nl.clear();
    const char* const data = buf.get();
    for (const char* p = data; (p = static_cast<const char*>(std::memchr(
                                    p, '\n', static_cast<std::size_t>(data + n - p))));
         ++p)
      nl.push_back(a + static_cast<std::size_t>(p - data));
    if (!reserved && !nl.empty()) {  // the range's rows, as dense as in its first buffer
      const std::size_t rows = nl.size() * ((part.hi - part.lo) / n + 1) * 9 / 8 + 16;
      part.table.rows = rows;
      reserve_rows(part.table, cols);  // no copy of the table as it grows
      part.begin.reserve(rows), part.end.reserve(rows), part.nl_index.reserve(rows);
      part.skip.reserve(rows);
      reserved = true;
    }
    const std::size_t before = part.parsed();
    if (!take_lines(file, part, cols, a, data, nl, spill)) {
      part.stopped = true;
      return;
    }
    if (rows_done) *rows_done += part.parsed() - before;
  }
}

// The header cell of the first deferred column (kNoRow: none).
std::size_t first_deferred_cell(const PoseTable& t) {
  return t.deferred_cells.empty() ? kNoRow : static_cast<std::size_t>(t.deferred_cells.front());
}

// Parses row 0 of `part`: the line from just after `prev` (the file's newline before the
// part's first one; kNoRow: none, the line is the header) up to `x`. False for a bad row.
bool take_first_line(const InputFile& file, const std::vector<int>& cols, std::size_t prev,
                     std::size_t x, Part& part) {
  if (x == kNoRow || prev == kNoRow) return true;
  std::vector<char> text(x - prev - 1);
  file.read(prev + 1, text.size(), text.data());
  const char* end = text.data() + text.size();
  if (end > text.data() && end[-1] == '\r') --end;
  if (end == text.data()) return true;  // blank
  if (part.table.rows == 0) part.table.rows = 1;
  int dicts = 0;
  const std::vector<Target> targets = make_targets(cols, part.table, dicts);
  part.first.dicts.resize(static_cast<std::size_t>(dicts));
  part.has_first = true;
  part.first_begin = prev + 1;
  part.first_end = prev + 1 + static_cast<std::size_t>(end - text.data());
  return parse_line(targets, 0, text.data(), end, part.first, part.mark, &part.first_skip);
}

// Appends rows [from, from + n) of src's selected columns to t's (the columns are reserved
// whole beforehand: their pages are touched as they fill, while the parts are freed).
void append_rows(PoseTable& src, std::size_t from, std::size_t n, PoseTable& t,
                 const std::vector<int>& cols) {
  const auto append = [&](auto& to, const auto& v, std::size_t k) {
    to.insert(to.end(), v.begin() + static_cast<std::ptrdiff_t>(from * k),
              v.begin() + static_cast<std::ptrdiff_t>((from + n) * k));
  };
  for (const int c : cols) {
    if (c < 0) continue;
    const PoseColumn a = pose_column(src, static_cast<std::size_t>(c));
    const PoseColumn b = pose_column(t, static_cast<std::size_t>(c));
    switch (a.spec->kind) {
      case CsvKind::floats: append(*b.floats, *a.floats, a.spec->numbers()); break;
      case CsvKind::integer: append(*b.ints, *a.ints, 1); break;
      case CsvKind::boolean:
        append(*b.bools, *a.bools, 1);
        append(*b.valid, *a.valid, 1);
        break;
      case CsvKind::string: append(b.strings->codes, a.strings->codes, 1); break;
    }
  }
}

// The parts' rows, in file order, into t (columns, line numbers, row bytes) and the string
// dictionaries merged in first-seen order. `base[k]`: newlines before part k.
void gather_rows(std::vector<std::unique_ptr<Part>>& parts, const std::vector<std::size_t>& base,
                 const std::vector<int>& cols, PoseTable& t) {
  t.rows = 0;
  for (const auto& p : parts) t.rows += p->parsed() + (p->has_first ? 1 : 0);
  reserve_rows(t, cols);
  std::vector<std::unique_ptr<Block>> blocks;
  std::size_t at = 0;
  for (std::size_t k = 0; k < parts.size(); ++k) {
    Part& p = *parts[k];
    for (int first = p.has_first ? 1 : 0; first >= 0; --first) {  // row 0, then the others
      const std::size_t n = first ? 1 : p.parsed();
      append_rows(p.table, first ? 0 : 1, n, t, cols);
      for (std::size_t r = 0; r < n; ++r) {
        t.line.push_back(static_cast<std::int64_t>(base[k] + (first ? 0 : p.nl_index[r]) + 1));
        t.row_begin.push_back(first ? p.first_begin : p.begin[r]);
        t.row_end.push_back(first ? p.first_end : p.end[r]);
        t.row_skip.push_back(first ? p.first_skip : p.skip[r]);
      }
      auto b = std::make_unique<Block>();
      b->lo = at, b->hi = at + n;
      b->dicts = std::move(first ? p.first.dicts : p.rows.dicts);
      blocks.push_back(std::move(b));
      at += n;
    }
    p.table = PoseTable();  // its memory back before the next part's copy
#ifdef __GLIBC__
    malloc_trim(0);  // the parts were filled by other threads: their arenas keep it otherwise
#endif
  }
  int dicts = 0;
  const std::vector<Target> targets = make_targets(cols, t, dicts);  // sized already
  for (auto& b : blocks) b->dicts.resize(static_cast<std::size_t>(dicts));  // the last line's
  merge_strings(blocks, targets);
}

// After the scan (parts in file order): the CRC-32, row 0 of every part, the last line
// when the file does not end with a newline (a part of its own), then the rows gathered
// into t. False when a row is bad (the caller reads the file again the two-pass way, which
// names the first bad row).
bool finish_parts(const InputFile& file, const std::vector<int>& cols,
                  std::vector<std::unique_ptr<Part>>& parts, PoseTable& t) {
  std::vector<std::size_t> base;
  std::size_t newlines = 0, prev = kNoRow;  // prev: the last newline so far
  for (std::size_t k = 0; k < parts.size(); ++k) {
    Part& p = *parts[k];
    if (p.stopped || !take_first_line(file, cols, prev, p.first_nl, p)) return false;
    t.file_crc32 = k == 0 ? p.crc
                          : static_cast<std::uint32_t>(crc32_combine(
                                t.file_crc32, p.crc, static_cast<z_off_t>(p.hi - p.lo)));
    base.push_back(newlines);
    newlines += p.newlines;
    if (p.last_nl != kNoRow) prev = p.last_nl;
  }
  if (prev != kNoRow && prev + 1 < file.size()) {  // the last line has no line end
    auto tail = std::make_unique<Part>();
    tail->lo = tail->hi = file.size();
    tail->mark = first_deferred_cell(t);
    if (!take_first_line(file, cols, prev, file.size(), *tail)) return false;
    parts.push_back(std::move(tail));
    base.push_back(newlines);
  }
  gather_rows(parts, base, cols, t);
  return true;
}

}  // namespace

void parse_rows(const InputFile& file, const Lines& lines, const std::vector<std::string>& header,
                const std::vector<int>& cols, PoseTable& t, int threads,
                std::atomic<std::uint64_t>* rows_done) {
  int dicts = 0;
  const std::vector<Target> targets = make_targets(cols, t, dicts);
  std::mutex mutex;
  std::vector<std::unique_ptr<Block>> blocks;
  parallel_for(t.rows, 64, [&](std::size_t lo, std::size_t hi) {
    auto b = std::make_unique<Block>();
    b->lo = lo, b->hi = hi;
    b->dicts.resize(static_cast<std::size_t>(dicts));
    parse_block(file, lines, targets, *b, rows_done);
    std::lock_guard<std::mutex> lock(mutex);
    blocks.push_back(std::move(b));
  }, threads);
  std::sort(blocks.begin(), blocks.end(), [](const auto& a, const auto& b) { return a->lo < b->lo; });
  for (const auto& b : blocks) {
    if (b->failed_row == kNoRow) continue;
    const std::size_t r = b->failed_row;
    std::string msg = t.path + ", line " + std::to_string(lines.number[r]) + ", " +
                      explain_row(b->failed_text, b->failed_cell, header, cols);
    if (r + 1 == lines.begin.size() && lines.last_unterminated)
      msg += " (the last line has no line end: is the file truncated?)";
    throw CsvParseError(msg);
  }
  merge_strings(blocks, targets);
}

bool scan_parse_rows(const InputFile& file, const std::vector<int>& cols, PoseTable& t,
                     int threads, std::atomic<std::uint64_t>* rows_done) {
  int dicts = 0;
  {
    PoseTable none;
    make_targets(cols, none, dicts);
  }
  std::mutex mutex;
  std::vector<std::unique_ptr<Part>> parts;
  parallel_for(file.size(), std::size_t{1} << 22, [&](std::size_t lo, std::size_t hi) {
    auto p = std::make_unique<Part>();
    p->lo = lo, p->hi = hi;
    p->mark = first_deferred_cell(t);
    scan_part(file, cols, dicts, *p, rows_done);
    std::lock_guard<std::mutex> lock(mutex);
    parts.push_back(std::move(p));
  }, threads);
  std::sort(parts.begin(), parts.end(), [](const auto& a, const auto& b) { return a->lo < b->lo; });
  return finish_parts(file, cols, parts, t);
}

}  // namespace bsp::csv_detail
