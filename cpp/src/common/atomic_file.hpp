// The one temp-then-rename helper of the core (the CSV, video and APNG writers): an output
// appears at its final name complete or not at all. Same naming scheme as Python's
// bsp_fast/atomic.py: a hidden `.NAME.tmp-PID-N` beside the target (same folder, so the
// rename is atomic; hidden, so nothing mistakes it for an output).
#pragma once
#include <string>

namespace bsp {

// `.NAME.tmp-PID-N` beside `target`, N counting up within the process.
std::string temp_name_for(const std::string& target);

// Owns the temporary name of one output. The writer creates and writes the file at path()
// its own way (open, fopen, avio_open) and closes it before commit(); commit() renames it
// over target(). Destroyed without a successful commit, it deletes the temporary file.
class AtomicFile {
 public:
  AtomicFile() = default;  // owns nothing
  explicit AtomicFile(std::string target);
  AtomicFile(AtomicFile&& o) noexcept;
  AtomicFile& operator=(AtomicFile&& o) noexcept;
  AtomicFile(const AtomicFile&) = delete;
  AtomicFile& operator=(const AtomicFile&) = delete;
  ~AtomicFile();

  const std::string& path() const { return tmp_; }  // the temporary file
  const std::string& target() const { return target_; }
  // Renames path() over target(). Returns 0, or the errno of the failed rename (the caller
  // throws its own error type; the temporary file is still removed on destruction).
  [[nodiscard]] int commit() noexcept;
  // Deletes the temporary file now (if not committed); the object then owns nothing.
  void discard() noexcept;

 private:
  std::string target_, tmp_;
  bool owned_ = false;
};

}  // namespace bsp
