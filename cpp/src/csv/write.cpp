// data.csv writer: the bytes pandas `DataFrame.to_csv(index=False)` wrote for the recorder's
// DataFrame (Python lists of floats, ints, True/False/None, str). Rows are formatted in
// parallel chunks and written in order to a temporary file that is renamed at the end.
#include <fcntl.h>
#include <unistd.h>

#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <stdexcept>

#include "bsp/common/errors.hpp"
#include "bsp/common/parallel.hpp"
#include "common/atomic_file.hpp"
#include "csv_internal.hpp"

namespace bsp {

std::size_t format_pyfloat(double v, char* out) {
  const char* special = std::isnan(v) ? "nan" : !std::isinf(v) ? nullptr : v < 0 ? "-inf" : "inf";
  if (special) {
    const std::size_t n = std::strlen(special);
    std::memcpy(out, special, n);
    return n;
  }
  char buf[40];  // shortest round trip, "[-]d[.ddd]e(+|-)xx"
  const char* stop = std::to_chars(buf, buf + sizeof buf, v, std::chars_format::scientific).ptr;
  const char* p = buf;
  char* o = out;
  if (*p == '-') *o++ = *p++;
  char digits[24];
  int n = 0;
  for (; *p != 'e'; ++p)
    if (*p != '.') digits[n++] = *p;
  const bool negative_exp = p[1] == '-';
  int e = 0;
  for (p += 2; p < stop; ++p) e = e * 10 + (*p - '0');
  if (negative_exp) e = -e;
  if (e < -4 || e >= 16) {  // Python's repr switches to exponent notation here
    *o++ = digits[0];
    if (n > 1) {
      *o++ = '.';
      o = std::copy(digits + 1, digits + n, o);
    }
    *o++ = 'e';
    *o++ = e < 0 ? '-' : '+';
    if (std::abs(e) < 10) *o++ = '0';  // at least two exponent digits: 1e-05
    o = std::to_chars(o, o + 4, std::abs(e)).ptr;
  } else if (e < 0) {  // 0.000ddd
    o = std::copy_n("0.000", 1 - e, o);
    o = std::copy(digits, digits + n, o);
  } else if (e + 1 < n) {  // ddd.ddd
    o = std::copy(digits, digits + e + 1, o);
    *o++ = '.';
    o = std::copy(digits + e + 1, digits + n, o);
  } else {  // ddd000.0
    o = std::copy(digits, digits + n, o);
    o = std::fill_n(o, e + 1 - n, '0');
    o = std::copy_n(".0", 2, o);
  }
  return static_cast<std::size_t>(o - out);
}

namespace {
using namespace csv_detail;

// A cell as Python's csv module writes it with QUOTE_MINIMAL (pandas' default).
std::string csv_quote(const std::string& s) {
  if (s.find_first_of(",\"\r\n") == std::string::npos) return s;
  std::string q = "\"";
  for (char c : s) {
    if (c == '"') q += '"';
    q += c;
  }
  return q + '"';
}

// Column sizes must match t.rows; string codes must index their dictionary.
void validate(PoseTable& t) {
  for (std::size_t c = 0; c < kPoseCsvColumnCount; ++c) {
    const CsvColumnSpec& s = kPoseCsvSpecs[c];
    const PoseColumn r = pose_column(t, c);
    const auto bad = [&](std::size_t have, std::size_t want, const char* what) {
      throw std::invalid_argument("write_pose_csv: column '" + std::string(s.name) + "' has " +
                                  std::to_string(have) + " " + what + ", expected " +
                                  std::to_string(want) + " (" + std::to_string(t.rows) +
                                  " rows)");
    };
    if (r.floats && r.floats->size() != t.rows * s.numbers())
      bad(r.floats->size(), t.rows * s.numbers(), "numbers");
    if (r.ints && r.ints->size() != t.rows) bad(r.ints->size(), t.rows, "values");
    if (r.bools && r.bools->size() != t.rows) bad(r.bools->size(), t.rows, "values");
    if (r.valid && !r.valid->empty() && r.valid->size() != t.rows)
      bad(r.valid->size(), t.rows, "validity flags");
    if (!r.strings) continue;
    if (r.strings->codes.size() != t.rows) bad(r.strings->codes.size(), t.rows, "codes");
    for (std::int32_t code : r.strings->codes)
      if (code < 0 || static_cast<std::size_t>(code) >= r.strings->values.size())
        throw std::invalid_argument("write_pose_csv: column '" + std::string(s.name) +
                                    "' has code " + std::to_string(code) + " outside its " +
                                    std::to_string(r.strings->values.size()) + " values");
  }
}

// Everything one row needs, resolved once per file.
struct RowFormat {
  PoseColumn refs[kPoseCsvColumnCount];
  std::vector<std::vector<std::string>> quoted;  // per column: its dictionary, CSV-quoted
  std::size_t bound = 0;                          // bytes one row can take at most

  explicit RowFormat(PoseTable& t) : quoted(kPoseCsvColumnCount) {
    bound = 1;  // '\n'
    for (std::size_t c = 0; c < kPoseCsvColumnCount; ++c) {
      refs[c] = pose_column(t, c);
      const CsvColumnSpec& s = kPoseCsvSpecs[c];
      std::size_t longest = 0;
      if (refs[c].strings)
        for (const std::string& v : refs[c].strings->values) {
          quoted[c].push_back(csv_quote(v));
          longest = std::max(longest, quoted[c].back().size());
        }
      bound += 1 + longest + 24;  // separator, string or int or bool
      bound += s.numbers() * (kPyFloatMaxChars + 2) + (s.outer + 2u) * 4u;
    }
  }
};

char* format_floats(const float* v, std::size_t n, char* o) {
  *o++ = '[';
  for (std::size_t i = 0; i < n; ++i) {
    if (i) *o++ = ',', *o++ = ' ';
    o += format_pyfloat(static_cast<double>(v[i]), o);
  }
  *o++ = ']';
  return o;
}

char* format_list_cell(const CsvColumnSpec& s, const float* v, char* o) {
  *o++ = '"';  // every list here has a comma, so pandas quotes it
  if (!s.outer) {
    o = format_floats(v, s.inner, o);
  } else {
    *o++ = '[';
    for (std::size_t j = 0; j < s.outer; ++j) {
      if (j) *o++ = ',', *o++ = ' ';
      o = format_floats(v + j * s.inner, s.inner, o);
    }
    *o++ = ']';
  }
  *o++ = '"';
  return o;
}

char* format_row(const RowFormat& f, std::size_t row, char* o) {
  for (std::size_t c = 0; c < kPoseCsvColumnCount; ++c) {
    if (c) *o++ = ',';
    const CsvColumnSpec& s = kPoseCsvSpecs[c];
    const PoseColumn& r = f.refs[c];
    switch (s.kind) {
      case CsvKind::string: {
        const std::string& v = f.quoted[c][static_cast<std::size_t>(r.strings->codes[row])];
        o = std::copy(v.begin(), v.end(), o);
        break;
      }
      case CsvKind::integer: o = std::to_chars(o, o + 24, (*r.ints)[row]).ptr; break;
      case CsvKind::floats: o = format_list_cell(s, r.floats->data() + row * s.numbers(), o); break;
      case CsvKind::boolean:
        if (r.valid->empty() || (*r.valid)[row]) {
          const bool b = (*r.bools)[row] != 0;
          o = std::copy_n(b ? "True" : "False", b ? 4 : 5, o);
        }
        break;
    }
  }
  *o++ = '\n';
  return o;
}

// The output file: written under AtomicFile's temporary name, renamed over `path` on
// commit(); removed if anything fails before that.
class OutputFile {
 public:
  explicit OutputFile(const std::string& path) : path_(path), out_(path) {
    fd_ = ::open(tmp().c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0644);
    if (fd_ < 0) fail("cannot create " + tmp());
  }
  ~OutputFile() {
    if (fd_ >= 0) ::close(fd_);
  }
  OutputFile(const OutputFile&) = delete;
  OutputFile& operator=(const OutputFile&) = delete;

  void write(const char* p, std::size_t n) {
    while (n) {
      const ssize_t w = ::write(fd_, p, n);
      if (w < 0 && errno == EINTR) continue;
      if (w < 0) fail("cannot write " + tmp());
      p += w;
      n -= static_cast<std::size_t>(w);
    }
  }
  void commit() {
    const int fd = fd_;
    fd_ = -1;
    if (::close(fd) != 0) fail("cannot close " + tmp());
    if (const int err = out_.commit()) {
      errno = err;
      fail("cannot rename " + tmp());
    }
  }

 private:
  const std::string& tmp() const { return out_.path(); }
  [[noreturn]] void fail(const std::string& what) {
    throw Error(path_ + ": " + what + ": " + std::strerror(errno));
  }
  std::string path_;
  AtomicFile out_;
  int fd_ = -1;
};

}  // namespace

void write_pose_csv(const std::string& path, const PoseTable& table, int threads) {
  // The writer only reads the table; pose_column hands out mutable pointers for the reader.
  PoseTable& t = const_cast<PoseTable&>(table);
  validate(t);
  const RowFormat format(t);
  if (threads <= 0) threads = num_threads();
  OutputFile file(path);
  std::string header;
  for (const char* name : kPoseCsvColumns) header += std::string(header.empty() ? "" : ",") + name;
  header += '\n';
  file.write(header.data(), header.size());

  constexpr std::size_t kChunkRows = 128;
  const std::size_t chunks_per_batch = 4 * static_cast<std::size_t>(threads);
  std::vector<std::vector<char>> bufs(chunks_per_batch);
  std::vector<std::size_t> used(chunks_per_batch);
  for (std::size_t first = 0; first < t.rows; first += kChunkRows * chunks_per_batch) {
    const std::size_t chunks =
        std::min(chunks_per_batch, (t.rows - first + kChunkRows - 1) / kChunkRows);
    parallel_for(chunks, 1, [&](std::size_t lo, std::size_t hi) {
      for (std::size_t k = lo; k < hi; ++k) {
        const std::size_t r0 = first + k * kChunkRows, r1 = std::min(t.rows, r0 + kChunkRows);
        bufs[k].resize(std::max(bufs[k].size(), (r1 - r0) * format.bound));
        char* o = bufs[k].data();
        for (std::size_t r = r0; r < r1; ++r) o = format_row(format, r, o);
        used[k] = static_cast<std::size_t>(o - bufs[k].data());
      }
    }, threads);
    for (std::size_t k = 0; k < chunks; ++k) file.write(bufs[k].data(), used[k]);
  }
  file.commit();
}

}  // namespace bsp
