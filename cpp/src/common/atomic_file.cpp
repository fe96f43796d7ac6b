#include "common/atomic_file.hpp"

#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <cstdio>
#include <utility>

namespace bsp {

std::string temp_name_for(const std::string& target) {
  static std::atomic<unsigned> counter{0};
  const std::size_t slash = target.find_last_of('/');
  const std::size_t name = slash == std::string::npos ? 0 : slash + 1;
  return target.substr(0, name) + "." + target.substr(name) + ".tmp-" +
         std::to_string(::getpid()) + "-" + std::to_string(counter++);
}

AtomicFile::AtomicFile(std::string target)
    : target_(std::move(target)), tmp_(temp_name_for(target_)), owned_(true) {}

AtomicFile::AtomicFile(AtomicFile&& o) noexcept
    : target_(std::move(o.target_)), tmp_(std::move(o.tmp_)), owned_(std::exchange(o.owned_, false)) {}

AtomicFile& AtomicFile::operator=(AtomicFile&& o) noexcept {
  if (this != &o) {
    discard();
    target_ = std::move(o.target_);
    tmp_ = std::move(o.tmp_);
    owned_ = std::exchange(o.owned_, false);
  }
  return *this;
}

AtomicFile::~AtomicFile() { discard(); }

int AtomicFile::commit() noexcept {
  if (!owned_) return EINVAL;
  if (std::rename(tmp_.c_str(), target_.c_str()) != 0) return errno;
  owned_ = false;
  return 0;
}

void AtomicFile::discard() noexcept {
  if (owned_) ::unlink(tmp_.c_str());
  owned_ = false;
}

}  // namespace bsp
