// Shared utilities: the deterministic parallel-for, the thread setting, the typed errors,
// the library versions and the temp-then-rename helper.
#include <doctest/doctest.h>

#include <algorithm>
#include <cerrno>
#include <atomic>
#include <filesystem>
#include <fstream>
#include <mutex>
#include <stdexcept>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include "bsp/common/diagnostics.hpp"
#include "bsp/common/errors.hpp"
#include "bsp/common/parallel.hpp"
#include "common/atomic_file.hpp"
#include "testing.hpp"

using namespace bsp;

namespace {
// The blocks parallel_for hands out for n items, sorted by start.
std::vector<std::pair<std::size_t, std::size_t>> blocks_of(std::size_t n, std::size_t min_block,
                                                           int threads) {
  std::mutex m;
  std::vector<std::pair<std::size_t, std::size_t>> blocks;
  parallel_for(
      n, min_block,
      [&](std::size_t lo, std::size_t hi) {
        std::lock_guard<std::mutex> lock(m);
        blocks.emplace_back(lo, hi);
      },
      threads);
  std::sort(blocks.begin(), blocks.end());
  return blocks;
}
}  // namespace

TEST_CASE("parallel_for: one contiguous block per thread, covering 0..n-1 once") {
  using Blocks = std::vector<std::pair<std::size_t, std::size_t>>;
  CHECK(blocks_of(10, 1, 1) == Blocks{{0, 10}});
  CHECK(blocks_of(10, 1, 2) == Blocks{{0, 5}, {5, 10}});
  CHECK(blocks_of(10, 1, 3) == Blocks{{0, 4}, {4, 8}, {8, 10}});
  CHECK(blocks_of(10, 1, 16) == blocks_of(10, 1, 10));  // never more blocks than items
  CHECK(blocks_of(10, 6, 4) == Blocks{{0, 10}});         // below min_block: inline
  CHECK(blocks_of(12, 6, 4) == Blocks{{0, 6}, {6, 12}});
  CHECK(blocks_of(0, 1, 4).empty());
  for (int threads : {1, 2, 3, 7}) {
    std::vector<std::atomic<int>> hits(1000);
    parallel_for(
        hits.size(), 1,
        [&](std::size_t lo, std::size_t hi) {
          for (std::size_t i = lo; i < hi; ++i) ++hits[i];
        },
        threads);
    for (const auto& h : hits) REQUIRE(h.load() == 1);
  }
}

TEST_CASE("parallel_for rethrows a block's exception after joining every thread") {
  std::atomic<int> finished{0};
  const auto run = [&] {
    parallel_for(
        4, 1,
        [&](std::size_t lo, std::size_t) {
          if (lo == 2) throw std::runtime_error("block at 2");
          ++finished;
        },
        4);
  };
  CHECK_THROWS_WITH_AS(run(), "block at 2", std::runtime_error);
  CHECK(finished.load() == 3);
}

TEST_CASE("set_num_threads: 0 means every core, negative counts as 0") {
  const unsigned hw = std::thread::hardware_concurrency();
  const int all = hw ? static_cast<int>(hw) : 1;
  set_num_threads(3);
  CHECK(num_threads() == 3);
  set_num_threads(-5);
  CHECK(num_threads() == all);
  set_num_threads(0);
  CHECK(num_threads() == all);
}

TEST_CASE("typed errors derive from bsp::Error, a std::runtime_error") {
  try {
    throw CsvParseError("data.csv, line 3: bad");
  } catch (const Error& e) {
    CHECK(std::string(e.what()) == "data.csv, line 3: bad");
  }
  CHECK_THROWS_AS(throw Hdf5Error("x"), std::runtime_error);
  CHECK_THROWS_AS(throw ApngError("x"), Error);
  CHECK_THROWS_AS(throw VideoDecodeError("x"), Error);
}

TEST_CASE("library_versions names the core and every library it links") {
  const auto v = library_versions();
  CHECK(v.at("bsp_core") == BSP_VERSION);
  for (const char* lib : {"ffmpeg", "libavcodec", "libavformat", "libavutil", "libswscale",
                          "opencv", "hdf5", "eigen", "assimp", "libdeflate", "compiler"})
    CHECK_MESSAGE(!v.at(lib).empty(), lib);
  CHECK(v.at("hdf5").find('.') != std::string::npos);
}

namespace {
std::vector<std::string> names_in(const std::filesystem::path& dir) {
  std::vector<std::string> names;
  for (const auto& e : std::filesystem::directory_iterator(dir)) names.push_back(e.path().filename());
  std::sort(names.begin(), names.end());
  return names;
}
}  // namespace

TEST_CASE("AtomicFile: hidden .NAME.tmp-PID-N beside the target, renamed on commit") {
  testing::TempDir tmp;
  const std::string target = tmp.path("out.bin");
  const std::string prefix = ".out.bin.tmp-" + std::to_string(::getpid()) + "-";
  AtomicFile a(target), b(target);
  CHECK(a.target() == target);
  CHECK(std::filesystem::path(a.path()).parent_path() == tmp.dir);
  const std::string name = std::filesystem::path(a.path()).filename();
  CHECK(name.rfind(prefix, 0) == 0);
  CHECK(name.size() > prefix.size());
  CHECK(a.path() != b.path());  // N counts up
  CHECK(temp_name_for("plain") .rfind(".plain.tmp-", 0) == 0);  // no folder: the working one
  std::ofstream(a.path()) << "complete";
  CHECK(names_in(tmp.dir) == std::vector<std::string>{name});
  REQUIRE(a.commit() == 0);
  CHECK(names_in(tmp.dir) == std::vector<std::string>{"out.bin"});
  std::ifstream in(target);
  std::string text;
  in >> text;
  CHECK(text == "complete");
  CHECK(a.commit() != 0);  // nothing left to commit
}

TEST_CASE("AtomicFile: destroyed or moved-over without commit, it deletes its temporary file") {
  testing::TempDir tmp;
  const std::string target = tmp.path("out.bin");
  std::ofstream(target) << "old";
  {
    AtomicFile a(target);
    std::ofstream(a.path()) << "partial";
    CHECK(names_in(tmp.dir).size() == 2);
  }
  CHECK(names_in(tmp.dir) == std::vector<std::string>{"out.bin"});  // the old output untouched
  AtomicFile moved;
  {
    AtomicFile a(target);
    std::ofstream(a.path()) << "partial";
    moved = std::move(a);  // ownership moves: a's destructor leaves the file alone
  }
  CHECK(names_in(tmp.dir).size() == 2);
  moved = AtomicFile();  // assigning over it deletes the file it owned
  CHECK(names_in(tmp.dir) == std::vector<std::string>{"out.bin"});
  AtomicFile c(tmp.path("missing/out.bin"));  // rename fails: errno comes back
  CHECK(c.commit() == ENOENT);
}
