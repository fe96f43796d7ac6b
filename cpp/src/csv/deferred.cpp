// Deferred float columns (csv.hpp, DeferredCells): parsed from the file when a caller needs
// a row's values, with the scanners the reader's hot loop uses, so the floats are the same.
#include <algorithm>
#include <cstring>

#include "bsp/common/errors.hpp"
#include "bsp/common/parallel.hpp"
#include "csv_internal.hpp"

namespace bsp {

struct DeferredCells::File {
  explicit File(const std::string& path) : in(path) {}
  csv_detail::InputFile in;
};

namespace {
[[noreturn]] void file_changed(const std::string& path) {
  throw CsvParseError(path + ": the file changed while it was being read (truncated or "
                      "rewritten by another process?)");
}

// Rows read with one pread at most: a clip's rows lie back to back in the file.
constexpr std::size_t kRunRows = 64;
}  // namespace

DeferredCells::DeferredCells(const PoseTable& table, const CsvReadOptions& read_options)
    : t_(table), options_(read_options), offsets_(kPoseCsvColumnCount, -1) {
  options_.deferred.clear();
  options_.rows_total = options_.rows_done = nullptr;
  for (std::size_t c = 0; c < kPoseCsvColumnCount; ++c) {  // kPoseCsvColumns order
    const auto& d = t_.deferred_columns;
    if (std::find(d.begin(), d.end(), static_cast<int>(c)) == d.end()) continue;
    offsets_[c] = static_cast<int>(per_row_);
    per_row_ += kPoseCsvSpecs[c].numbers();
  }
  file_ = std::make_unique<File>(t_.path);
  if (file_->in.size() != t_.file_bytes || file_->in.mtime_ns() != t_.file_mtime_ns)
    file_changed(t_.path);
}

DeferredCells::~DeferredCells() = default;

int DeferredCells::offset_of(int index) const {
  return index >= 0 && index < static_cast<int>(kPoseCsvColumnCount)
             ? offsets_[static_cast<std::size_t>(index)] : -1;
}

namespace {
// Parses the deferred cells of one row's text [p, end) (row `row` of the table) into out
// (each column at its offset); false on a malformed cell. The reader recorded where the
// first deferred cell begins (row_skip); other cells up to the last deferred one are
// stepped over as the reader skips unselected cells (the reader already checked them, so
// the boundaries are those it found).
bool parse_row(const char* p, const char* end, const PoseTable& t, const std::vector<int>& offsets,
               std::size_t row, float* out) {
  using namespace csv_detail;
  std::size_t next = 0;  // the next deferred cell (header order)
  const std::size_t n = t.header_cells, last = static_cast<std::size_t>(t.deferred_cells.back());
  std::size_t c = 0;  // the reader found where the first deferred cell begins: start there
  if (row < t.row_skip.size() && t.row_skip[row] != PoseTable::kUnknownSkip &&
      t.row_skip[row] <= static_cast<std::size_t>(end - p)) {
    p += t.row_skip[row];
    c = static_cast<std::size_t>(t.deferred_cells.front());
  }
  for (; c <= last; ++c) {
    bool ok;
    if (static_cast<std::size_t>(t.deferred_cells[next]) == c) {
      const auto column = static_cast<std::size_t>(t.deferred_columns[next++]);
      ok = scan_list_cell(p, end, kPoseCsvSpecs[column], out + offsets[column]);
    } else {
      std::string_view raw;
      bool escaped = false;
      ok = scan_string_cell(p, end, raw, escaped);
    }
    if (!ok || !(c + 1 < n ? (p < end && *p++ == ',') : p == end)) return false;
  }
  return true;
}
}  // namespace

void DeferredCells::read(const std::size_t* rows, std::size_t count, float* out,
                         std::vector<char>& buf) const {
  if (per_row_ == 0) return;
  for (std::size_t k = 0; k < count;) {
    std::size_t e = k + 1;  // rows [k, e) lie back to back: one read
    while (e < count && e - k < kRunRows && rows[e] == rows[e - 1] + 1) ++e;
    const std::uint64_t from = t_.row_begin[rows[k]], to = t_.row_end[rows[e - 1]];
    if (buf.size() < to - from) buf.resize(to - from);
    try {
      file_->in.read(from, to - from, buf.data());
    } catch (const csv_detail::FileChanged&) {
      file_changed(t_.path);
    }
    for (; k < e; ++k) {
      const char* line = buf.data() + (t_.row_begin[rows[k]] - from);
      const char* stop = buf.data() + (t_.row_end[rows[k]] - from);
      if (!parse_row(line, stop, t_, offsets_, rows[k], out + k * per_row_))
        throw DeferredCellError{};
    }
  }
}

void DeferredCells::check_rows(const std::vector<std::uint8_t>& done, int threads) const {
  std::vector<std::size_t> rest;
  for (std::size_t r = 0; r < t_.rows; ++r)
    if (!done[r]) rest.push_back(r);
  parallel_for(rest.size(), kRunRows, [&](std::size_t lo, std::size_t hi) {
    std::vector<float> out(kRunRows * per_row_);
    std::vector<char> buf;
    for (std::size_t k = lo; k < hi; k += kRunRows)
      read(rest.data() + k, std::min(kRunRows, hi - k), out.data(), buf);
  }, threads);
  try {
    file_->in.check_unchanged();
  } catch (const csv_detail::FileChanged&) {
    file_changed(t_.path);
  }
}

void DeferredCells::throw_parse_error() const {
  read_pose_csv(t_.path, options_);  // throws for the first bad row, as without deferring
  file_changed(t_.path);  // it read cleanly: the file is not what the deferred reads saw
}

}  // namespace bsp
