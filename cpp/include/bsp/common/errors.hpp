// Typed exceptions of the core. Each is registered with pybind11 under the same name, so
// Python code catches bsp_fast.CsvParseError and friends. Messages always name the file and
// the row, column or frame, plus the underlying library's own reason.
#pragma once
#include <exception>
#include <stdexcept>
#include <string>

namespace bsp {

class Error : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

#define BSP_DECLARE_ERROR(Name) \
  class Name : public Error {   \
   public:                      \
    using Error::Error;         \
  }

BSP_DECLARE_ERROR(CsvParseError);
BSP_DECLARE_ERROR(VideoDecodeError);
BSP_DECLARE_ERROR(VideoEncodeError);
BSP_DECLARE_ERROR(ApngError);
BSP_DECLARE_ERROR(Hdf5Error);
BSP_DECLARE_ERROR(MotionError);

#undef BSP_DECLARE_ERROR

// Which of the exceptions above (or of the standard ones the core throws) an exception is,
// for carrying it as a value across a process boundary (a shard's media failure) and
// raising the same type on the other side. Registered with pybind11 as _core.ErrorKind;
// ValueError = std::invalid_argument, MemoryError = std::bad_alloc, RuntimeError = others.
enum class ErrorKind : int {
  Error, CsvParseError, VideoDecodeError, VideoEncodeError, ApngError, Hdf5Error, MotionError,
  ValueError, MemoryError, RuntimeError
};
ErrorKind error_kind(const std::exception_ptr& e);
// Throws an exception of `kind` with `message` (MemoryError: std::bad_alloc, no message).
[[noreturn]] void throw_error(ErrorKind kind, const std::string& message);

}  // namespace bsp
