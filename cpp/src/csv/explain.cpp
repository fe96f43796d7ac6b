// The reader's cold path: once the hot loop has stopped on a row, re-read that row slowly
// and say what was expected and what was found. Nothing here runs for a valid file, so it
// favours clear messages over speed.
#include <string>
#include <vector>

#include "csv_internal.hpp"

namespace bsp::csv_detail {
namespace {

struct Cell {
  std::string_view text;  // raw, quotes included
  bool unterminated = false;
};

// Quote-aware split of one line; an unterminated quote ends the split (last cell flagged).
std::vector<Cell> split_cells(std::string_view row) {
  std::vector<Cell> cells;
  std::size_t i = 0;
  for (;;) {
    const std::size_t start = i;
    if (i < row.size() && row[i] == '"') {
      ++i;
      for (;; ++i) {
        if (i >= row.size()) {
          cells.push_back({row.substr(start), true});
          return cells;
        }
        if (row[i] == '"') {
          if (i + 1 < row.size() && row[i + 1] == '"') ++i;
          else break;
        }
      }
    }
    while (i < row.size() && row[i] != ',') ++i;
    cells.push_back({row.substr(start, i - start), false});
    if (i >= row.size()) return cells;
    ++i;  // a trailing ',' leaves one more, empty, cell
  }
}

std::string_view trim(std::string_view s) {
  while (!s.empty() && s.front() == ' ') s.remove_prefix(1);
  while (!s.empty() && s.back() == ' ') s.remove_suffix(1);
  return s;
}

bool is_number(std::string_view tok) {
  float v;
  const auto r = fast_float::from_chars(tok.data(), tok.data() + tok.size(), v);
  return !tok.empty() && r.ec == std::errc() && r.ptr == tok.data() + tok.size();
}

// A loosely parsed list cell: a number token or a list of items.
struct Item {
  bool list = false;
  std::string_view token;
  std::vector<Item> kids;
};

bool parse_item(std::string_view s, std::size_t& i, Item& out, std::string& err, int depth) {
  while (i < s.size() && s[i] == ' ') ++i;
  if (i >= s.size() || s[i] != '[') {
    std::size_t j = i;
    while (j < s.size() && s[j] != ',' && s[j] != ']' && s[j] != '[') ++j;
    out.token = trim(s.substr(i, j - i));
    i = j;
    return true;
  }
  if (depth > 2) {
    err = "expected numbers, found lists nested " + std::to_string(depth + 1) + " deep";
    return false;
  }
  out.list = true;
  ++i;
  while (i < s.size() && s[i] == ' ') ++i;
  if (i < s.size() && s[i] == ']') return ++i, true;
  for (;;) {
    out.kids.emplace_back();
    if (!parse_item(s, i, out.kids.back(), err, depth + 1)) return false;
    while (i < s.size() && s[i] == ' ') ++i;
    if (i >= s.size()) {
      err = "expected ',' or ']', found the end of the cell (truncated list)";
      return false;
    }
    if (s[i] == ']') return ++i, true;
    if (s[i] != ',') {
      err = "expected ',' or ']', found " + snippet(s.substr(i));
      return false;
    }
    ++i;
  }
}

// Checks the numbers of one flat list; `where` is "" or " in list 3".
std::string check_numbers(const Item& list, std::size_t want, const std::string& what,
                          const std::string& where) {
  if (list.kids.size() != want)
    return "expected " + what + ", got " + std::to_string(list.kids.size()) + " numbers" + where;
  for (std::size_t k = 0; k < list.kids.size(); ++k) {
    const Item& it = list.kids[k];
    const std::string pos = where + " at item " + std::to_string(k + 1);
    if (it.list) return "expected a number" + pos + ", found a list";
    if (!is_number(it.token)) return "expected a number" + pos + ", found " + snippet(it.token);
  }
  return {};
}

std::string explain_list(std::string_view content, const CsvColumnSpec& spec) {
  if (trim(content).empty()) return {};
  const std::string what = spec.outer ? std::to_string(spec.outer) + " x " +
                                            std::to_string(spec.inner) + " numbers"
                                      : std::to_string(spec.inner) + " numbers";
  Item top;
  std::string err;
  std::size_t i = 0;
  if (!parse_item(content, i, top, err, 0)) return err;
  if (!top.list) return "expected a list '[...]' of " + what + ", found " + snippet(content);
  while (i < content.size() && content[i] == ' ') ++i;
  if (i < content.size())
    return "expected the end of the list, found " + snippet(content.substr(i));
  if (!spec.outer) return check_numbers(top, spec.inner, what, "");
  if (top.kids.size() != spec.outer)
    return "expected " + what + ", got " + std::to_string(top.kids.size()) + " lists";
  for (std::size_t j = 0; j < top.kids.size(); ++j) {
    const Item& kid = top.kids[j];
    const std::string where = " in list " + std::to_string(j + 1);
    if (!kid.list) return "expected " + what + ", found " + snippet(kid.token) + where;
    std::string msg = check_numbers(kid, spec.inner, what, where);
    if (!msg.empty()) return msg;
  }
  return {};
}

bool is_int(std::string_view s, std::int64_t& v) {
  const char* p = s.data();
  const char* end = p + s.size();
  return !s.empty() && scan_int_cell(p, end, &v) && p == end;
}

bool is_bool(std::string_view s) {
  std::uint8_t v, ok;
  const char* p = s.data();
  const char* end = p + s.size();
  return scan_bool_cell(p, end, &v, &ok) && p == end;
}

// What is wrong with one cell ("" if nothing is).
std::string explain_cell(std::string_view text, int col) {
  std::string_view content = text;
  if (!text.empty() && text.front() == '"') {
    std::size_t close = 1;
    while (close < text.size() && !(text[close] == '"' && (close + 1 >= text.size() ||
                                                           text[close + 1] != '"')))
      close += text[close] == '"' ? 2 : 1;
    if (close + 1 < text.size())
      return "expected ',' after the closing quote, found " + snippet(text.substr(close + 1));
    content = text.substr(1, close - 1);
  }
  if (col < 0) return {};
  const CsvColumnSpec& spec = kPoseCsvSpecs[col];
  switch (spec.kind) {
    case CsvKind::string: return {};
    case CsvKind::integer:
      if (text.empty()) return "expected an integer, found an empty cell";
      {
        std::int64_t v = 0;
        if (!is_int(text, v)) return "expected an integer, found " + snippet(text);
        const IntRange r = int_range(col);
        if (v < r.lo || v > r.hi)
          return std::string("expected ") + r.what + " from " + std::to_string(r.lo) + " to " +
                 std::to_string(r.hi) + ", found " + snippet(text) +
                 (v < r.lo ? " (out of range: too small)" : " (out of range: too large)");
        return {};
      }
    case CsvKind::boolean:
      return is_bool(text) ? std::string()
                           : "expected True, False or an empty cell, found " + snippet(text);
    case CsvKind::floats:
      if (!text.empty() && text.front() != '"')
        return "expected a double-quoted list \"[...]\", found " + snippet(text);
      return explain_list(content, spec);
  }
  return {};
}

}  // namespace

std::string explain_row(std::string_view row, std::size_t failed_cell,
                        const std::vector<std::string>& header,
                        const std::vector<int>& header_cols) {
  const std::vector<Cell> cells = split_cells(row);
  const auto name = [&](std::size_t c) {
    return "column '" + (c < header.size() ? header[c] : std::string("?")) + "': ";
  };
  const std::size_t last = cells.size() - 1;
  if (cells[last].unterminated && last <= failed_cell)
    return name(last) + "expected a closing '\"' before the end of the line, found " +
           snippet(cells[last].text.substr(cells[last].text.size() > 30
                                               ? cells[last].text.size() - 30 : 0)) +
           " at the end (unterminated quote: truncated line?)";
  if (failed_cell < cells.size() && failed_cell < header.size()) {
    const std::string msg = explain_cell(cells[failed_cell].text, header_cols[failed_cell]);
    if (!msg.empty()) return name(failed_cell) + msg;
  }
  const std::string counts = "expected " + std::to_string(header.size()) + " cells, found " +
                             std::to_string(cells.size());
  if (cells.size() < header.size())
    return name(cells.size()) + counts + " (the row ends before this column)";
  if (cells.size() > header.size())
    return name(header.size() - 1) + counts + " (extra text after the last column: " +
           snippet(cells[header.size()].text) + ")";
  return name(failed_cell) + "could not parse the cell, found " +
         snippet(failed_cell < cells.size() ? cells[failed_cell].text : row);
}

}  // namespace bsp::csv_detail
