// A minimal deterministic parallel-for: the index range is cut into one contiguous block
// per thread, so each output element is computed by exactly the same code whatever the
// thread count (results are bitwise identical for 1..N threads).
#pragma once
#include <algorithm>
#include <cstddef>
#include <exception>
#include <thread>
#include <vector>

namespace bsp {

// 0 = use std::thread::hardware_concurrency().
void set_num_threads(int n);
int num_threads();

// Calls fn(begin, end) on disjoint blocks covering [0, n). Runs inline when n is below
// min_block (thread start-up costs ~50 us). Rethrows the first exception of any block.
template <class Fn>
void parallel_for(std::size_t n, std::size_t min_block, Fn&& fn, int threads = 0) {
  if (threads <= 0) threads = num_threads();
  std::size_t blocks = std::min<std::size_t>(static_cast<std::size_t>(threads),
                                             min_block ? n / min_block : n);
  if (blocks <= 1) {
    if (n) fn(std::size_t{0}, n);
    return;
  }
  std::vector<std::thread> pool;
  std::vector<std::exception_ptr> errors(blocks);
  const std::size_t step = (n + blocks - 1) / blocks;
  for (std::size_t b = 0; b < blocks; ++b) {
    const std::size_t lo = b * step, hi = std::min(n, lo + step);
    if (lo >= hi) break;
    pool.emplace_back([&, b, lo, hi] {
      try {
        fn(lo, hi);
      } catch (...) {
        errors[b] = std::current_exception();
      }
    });
  }
  for (auto& t : pool) t.join();
  for (auto& e : errors)
    if (e) std::rethrow_exception(e);
}

}  // namespace bsp
