// Typed exceptions of the core. Each is registered with pybind11 under the same name, so
// Python code catches bsp_fast.CsvParseError and friends. Messages always name the file and
// the row, column or frame, plus the underlying library's own reason.
#pragma once
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

}  // namespace bsp
