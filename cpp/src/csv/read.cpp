// data.csv reader: mmap, line index, header, then parallel row parsing straight into the
// preallocated columns of a PoseTable (SPEC section 1).
#include <fcntl.h>
#include <signal.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

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
namespace {
using namespace csv_detail;

// Read-only mapping of a whole file; the reader never copies the text.
class MappedFile {
 public:
  explicit MappedFile(const std::string& path) {
    fd_ = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
    if (fd_ < 0) throw CsvParseError(path + ": cannot open: " + std::strerror(errno));
    struct stat st {};
    if (::fstat(fd_, &st) != 0) close_and_throw(path, "cannot stat");
    size_ = static_cast<std::size_t>(st.st_size);
    if (size_ == 0) return;
    void* map = ::mmap(nullptr, size_, PROT_READ, MAP_PRIVATE, fd_, 0);
    if (map == MAP_FAILED) close_and_throw(path, "cannot mmap");
    map_ = map;
    ::madvise(map_, size_, MADV_SEQUENTIAL);
  }
  ~MappedFile() {
    if (map_) ::munmap(map_, size_);
    if (fd_ >= 0) ::close(fd_);
  }
  MappedFile(const MappedFile&) = delete;
  MappedFile& operator=(const MappedFile&) = delete;
  const char* data() const { return static_cast<const char*>(map_); }
  std::size_t size() const { return size_; }

 private:
  // The destructor does not run when the constructor throws, so close here.
  [[noreturn]] void close_and_throw(const std::string& path, const char* what) {
    const int err = errno;
    ::close(fd_);
    fd_ = -1;
    throw CsvParseError(path + ": " + what + ": " + std::strerror(err));
  }
  int fd_ = -1;
  void* map_ = nullptr;
  std::size_t size_ = 0;
};

}  // namespace

void csv_detail::release_pages(const char* base, std::size_t from, std::size_t to) {
  static const std::size_t page = static_cast<std::size_t>(::sysconf(_SC_PAGESIZE));
  const std::size_t lo = (from + page - 1) / page * page, hi = to / page * page;
  if (hi > lo) ::madvise(const_cast<char*>(base) + lo, hi - lo, MADV_DONTNEED);
}

namespace {
std::mutex g_sigbus_mutex;
int g_sigbus_users = 0;
struct sigaction g_sigbus_previous {};

void on_sigbus(int sig, siginfo_t* info, void* ctx) {
  if (sigjmp_buf* target = csv_detail::sigbus_jump()) siglongjmp(*target, 1);
  // Not a read of ours: hand it to whoever had SIGBUS before, or die as by default.
  const struct sigaction& prev = g_sigbus_previous;
  if ((prev.sa_flags & SA_SIGINFO) && prev.sa_sigaction) return prev.sa_sigaction(sig, info, ctx);
  if (prev.sa_handler != SIG_DFL && prev.sa_handler != SIG_IGN) return prev.sa_handler(sig);
  ::signal(SIGBUS, SIG_DFL);
  ::raise(SIGBUS);
}
}  // namespace

sigjmp_buf*& csv_detail::sigbus_jump() {
  thread_local sigjmp_buf* target = nullptr;
  return target;
}

csv_detail::SigbusGuard::SigbusGuard() {
  std::lock_guard<std::mutex> lock(g_sigbus_mutex);
  if (g_sigbus_users++ > 0) return;
  struct sigaction sa {};
  sa.sa_sigaction = on_sigbus;
  sa.sa_flags = SA_SIGINFO | SA_NODEFER;
  sigemptyset(&sa.sa_mask);
  ::sigaction(SIGBUS, &sa, &g_sigbus_previous);
}

csv_detail::SigbusGuard::~SigbusGuard() {
  std::lock_guard<std::mutex> lock(g_sigbus_mutex);
  if (--g_sigbus_users == 0) ::sigaction(SIGBUS, &g_sigbus_previous, nullptr);
}

namespace {

// Offsets of every '\n', found in parallel over byte ranges (memchr-bound), each flagged
// when a '\r' precedes it. The flag is taken while the page is hot, so the index below
// never touches the text again and released pages stay released.
struct Newlines {
  std::vector<std::size_t> pos;
  std::vector<std::uint8_t> cr;
};

[[noreturn]] void throw_file_changed() {
  throw csv_detail::FileChanged();
}

Newlines find_newlines(const char* data, std::size_t size, int threads) {
  std::mutex mutex;
  std::vector<std::pair<std::size_t, Newlines>> parts;
  parallel_for(size, std::size_t{1} << 22, [&](std::size_t lo, std::size_t hi) {
    Newlines found;
    const bool whole = csv_detail::guarded([&] {
      for (std::size_t a = lo; a < hi; a += kReleaseBytes) {
        const std::size_t b = std::min(hi, a + kReleaseBytes);
        for (const char* p = data + a; p < data + b; ++p) {
          p = static_cast<const char*>(std::memchr(p, '\n', static_cast<std::size_t>(data + b - p)));
          if (!p) break;
          found.pos.push_back(static_cast<std::size_t>(p - data));
          found.cr.push_back(p > data && p[-1] == '\r');
        }
        release_pages(data, a, b);
      }
    });
    if (!whole) throw_file_changed();
    std::lock_guard<std::mutex> lock(mutex);
    parts.emplace_back(lo, std::move(found));
  }, threads);
  std::sort(parts.begin(), parts.end(),
            [](const auto& a, const auto& b) { return a.first < b.first; });
  Newlines all;
  for (auto& part : parts) {
    all.pos.insert(all.pos.end(), part.second.pos.begin(), part.second.pos.end());
    all.cr.insert(all.cr.end(), part.second.cr.begin(), part.second.cr.end());
  }
  return all;
}

// Splits the file into the header and the non-blank data lines ('\r\n' or '\n').
Lines index_lines(const char* data, std::size_t size, int threads) {
  const Newlines nl = find_newlines(data, size, threads);
  Lines lines;
  lines.last_unterminated = nl.pos.empty() || nl.pos.back() + 1 != size;
  const std::size_t count = nl.pos.size() + (lines.last_unterminated ? 1 : 0);
  lines.begin.reserve(count);
  lines.end.reserve(count);
  lines.number.reserve(count);
  std::size_t start = 0;
  for (std::size_t k = 0; k < count; ++k) {
    std::size_t stop = k < nl.pos.size() ? nl.pos[k] : size;
    const std::size_t next = stop + 1;
    const bool cr = k < nl.pos.size() ? nl.cr[k] != 0 : (stop > start && data[stop - 1] == '\r');
    if (cr && stop > start) --stop;
    if (k == 0) {
      lines.header = std::string_view(data + start, stop - start);
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
  return wanted;
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

void parse_file(const char* data, std::size_t size, const std::string& path,
                const CsvReadOptions& opt, const std::vector<bool>& wanted, int threads,
                PoseTable& t);

}  // namespace

PoseTable read_pose_csv(const std::string& path, const CsvReadOptions& opt) {
  const std::vector<bool> wanted = wanted_columns(opt);
  const int threads = opt.threads > 0 ? opt.threads : num_threads();
  MappedFile file(path);
  if (file.size() == 0) throw CsvParseError(path + ", line 1 (header): empty file, no header");
  // Another process may truncate the file while it is mapped: every read of the mapping is
  // guarded, and a SIGBUS becomes this error instead of killing the process.
  csv_detail::SigbusGuard sigbus;
  PoseTable t;
  try {
    if (csv_detail::guarded([&] { parse_file(file.data(), file.size(), path, opt, wanted,
                                             threads, t); }))
      return t;
  } catch (const csv_detail::FileChanged&) {
  }
  throw CsvParseError(path + ": the file changed while it was being read (truncated by "
                      "another process?); nothing was parsed");
}

namespace {
void parse_file(const char* data, std::size_t size, const std::string& path,
                const CsvReadOptions& opt, const std::vector<bool>& wanted, int threads,
                PoseTable& t) {
  t.path = path;
  const csv_detail::Lines lines = index_lines(data, size, threads);
  // A '\r' left inside the first line means CR-only line ends (classic Mac): the whole
  // file would read as a header and no rows. Refused rather than converted to nothing.
  if (const std::size_t cr = lines.header.find('\r'); cr != std::string_view::npos)
    throw CsvParseError(path + ", line 1 (header): found a carriage return without a line "
                        "feed at byte " + std::to_string(cr) + ": CR-only line ends are not "
                        "supported (expected '\\n' or '\\r\\n' line ends)");
  const std::vector<std::string> names = split_header(lines.header, path);
  const std::vector<int> cols = map_header(names, wanted, opt, t);
  t.rows = lines.begin.size();
  t.line = lines.number;
  if (opt.rows_total) *opt.rows_total = t.rows;
  csv_detail::parse_rows(data, lines, names, cols, t, threads, opt.rows_done);
  if (opt.check_duplicates) check_duplicates(t);
}
}  // namespace

}  // namespace bsp
