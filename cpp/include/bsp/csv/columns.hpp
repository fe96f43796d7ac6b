// The data.csv schema column by column: each column's kind and array shape, the PoseTable
// members that hold it, and the UTF-8 check of its strings. This lets code that moves a
// table across a boundary (the Python binding) go by column name without knowing the
// PoseTable's members or the parser's internals.
#pragma once
#include <cstddef>
#include <cstdint>
#include <string_view>
#include <vector>

#include "bsp/csv/csv.hpp"

namespace bsp {

enum class CsvKind : std::uint8_t { string, integer, floats, boolean };

struct CsvColumnSpec {
  const char* name;     // canonical name (kPoseCsvColumns spelling)
  CsvKind kind;
  std::uint16_t outer;  // float lists: lists per cell for nested cells, 0 for a flat list
  std::uint16_t inner;  // float lists: numbers per (inner) list; 0 for other kinds
  // Numbers per row of a float list column (0 for the other kinds).
  std::size_t numbers() const { return outer ? std::size_t{outer} * inner : inner; }
  // Shape of the column's array for `rows` rows: (rows,) for strings (codes), integers and
  // booleans, (rows, inner) for a flat list, (rows, outer, inner) for a nested one.
  std::vector<std::size_t> shape(std::size_t rows) const;
};

// The 24 columns in kPoseCsvColumns order.
extern const CsvColumnSpec kPoseCsvSpecs[kPoseCsvColumnCount];

// Index of a column name in kPoseCsvColumns (the crossing alias gives the crossing column's
// index), or -1 for any other name.
int pose_csv_column_index(std::string_view name);

// The PoseTable members that hold one column; only those of the column's kind are set.
struct PoseColumn {
  const CsvColumnSpec* spec = nullptr;
  StringColumn* strings = nullptr;            // string columns
  std::vector<std::int64_t>* ints = nullptr;  // integer columns
  std::vector<float>* floats = nullptr;       // float list columns (rows * numbers())
  std::vector<std::uint8_t>* bools = nullptr;  // boolean columns: values
  std::vector<std::uint8_t>* valid = nullptr;  // boolean columns: 0 = empty cell
};

// Column `index` (0..23) of `t`; throws std::out_of_range for any other index.
PoseColumn pose_column(PoseTable& t, std::size_t index);
// Column `name` (either crossing name accepted); throws std::invalid_argument naming it and
// the allowed names for an unknown one.
PoseColumn pose_column(PoseTable& t, std::string_view name);

// Checks the strings of the columns that were read (t.columns_present, in that order, each
// dictionary in first-seen order) against UTF-8 as Python's strict decoder defines it: no
// overlong forms, no surrogates, nothing above U+10FFFF, no truncated sequences. Throws
// CsvParseError "<path>, column '<name>': value '<text>' is not valid UTF-8" for the first
// bad one; <text> shows bytes >= 0x80 as \xNN, so the message itself is valid UTF-8.
// read_pose_csv does not check (bytes are kept as they are): call this before handing the
// strings to something that needs text.
void check_utf8(const PoseTable& t);

// True when `s` is valid UTF-8 in the sense above.
bool is_valid_utf8(std::string_view s);

}  // namespace bsp
