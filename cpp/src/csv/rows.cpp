// The reader's hot loop: blocks of rows parsed in parallel, each thread reading its rows a
// buffer at a time and writing straight into the preallocated columns. Strings are
// dictionary-encoded per block and the block dictionaries merged in file order afterwards,
// so codes (first-seen order) and every other value are identical for any thread count.
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

// Parses rows [b.lo, b.hi), reading them from the file about kScanBytes at a time (at least
// one whole row); stops at the first bad row and records where.
void parse_block(const InputFile& file, const Lines& lines, const std::vector<Target>& targets,
                 Block& b, std::atomic<std::uint64_t>* rows_done) {
  const std::size_t n = targets.size();
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
      const char* const line = buf.data() + (lines.begin[row] - from);
      const char* p = line;
      const char* end = buf.data() + (lines.end[row] - from);
      for (std::size_t c = 0; c < n; ++c) {
        const bool ok = parse_cell(targets[c], row, p, end, b) &&
                        (c + 1 < n ? (p < end && *p++ == ',') : p == end);
        if (!ok) {
          b.failed_row = row;
          b.failed_cell = c;
          b.failed_text.assign(line, end);
          return;
        }
      }
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

}  // namespace bsp::csv_detail
