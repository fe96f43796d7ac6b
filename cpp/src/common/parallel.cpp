#include "bsp/common/parallel.hpp"

#include <atomic>

namespace bsp {
namespace {
std::atomic<int> g_threads{0};
}

void set_num_threads(int n) { g_threads = n < 0 ? 0 : n; }

int num_threads() {
  const int n = g_threads.load();
  if (n > 0) return n;
  const unsigned hw = std::thread::hardware_concurrency();
  return hw ? static_cast<int>(hw) : 1;
}

}  // namespace bsp
