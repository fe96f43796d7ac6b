// Helpers shared by the C++ tests.
#pragma once
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <string>

namespace bsp::testing {

// A scratch directory, removed with everything in it at the end of the test.
struct TempDir {
  std::filesystem::path dir;
  explicit TempDir(const std::string& prefix = "bsp_test") {
    static int n = 0;
    dir = std::filesystem::temp_directory_path() /
          (prefix + "_" + std::to_string(::getpid()) + "_" + std::to_string(n++));
    std::filesystem::create_directories(dir);
  }
  ~TempDir() { std::filesystem::remove_all(dir); }
  TempDir(const TempDir&) = delete;
  TempDir& operator=(const TempDir&) = delete;
  std::string path(const std::string& name) const { return (dir / name).string(); }
  // Writes `text` to `name` in the directory; returns its path.
  std::string write(const std::string& name, const std::string& text) const {
    const std::string p = path(name);
    std::ofstream(p, std::ios::binary) << text;
    return p;
  }
};

}  // namespace bsp::testing
