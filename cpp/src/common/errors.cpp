#include "bsp/common/errors.hpp"

#include <new>

namespace bsp {

ErrorKind error_kind(const std::exception_ptr& e) {
  try {
    std::rethrow_exception(e);
  } catch (const CsvParseError&) {
    return ErrorKind::CsvParseError;
  } catch (const VideoDecodeError&) {
    return ErrorKind::VideoDecodeError;
  } catch (const VideoEncodeError&) {
    return ErrorKind::VideoEncodeError;
  } catch (const ApngError&) {
    return ErrorKind::ApngError;
  } catch (const Hdf5Error&) {
    return ErrorKind::Hdf5Error;
  } catch (const MotionError&) {
    return ErrorKind::MotionError;
  } catch (const Error&) {
    return ErrorKind::Error;
  } catch (const std::invalid_argument&) {
    return ErrorKind::ValueError;
  } catch (const std::bad_alloc&) {
    return ErrorKind::MemoryError;
  } catch (...) {
    return ErrorKind::RuntimeError;
  }
}

void throw_error(ErrorKind kind, const std::string& message) {
  switch (kind) {
    case ErrorKind::Error: throw Error(message);
    case ErrorKind::CsvParseError: throw CsvParseError(message);
    case ErrorKind::VideoDecodeError: throw VideoDecodeError(message);
    case ErrorKind::VideoEncodeError: throw VideoEncodeError(message);
    case ErrorKind::ApngError: throw ApngError(message);
    case ErrorKind::Hdf5Error: throw Hdf5Error(message);
    case ErrorKind::MotionError: throw MotionError(message);
    case ErrorKind::ValueError: throw std::invalid_argument(message);
    case ErrorKind::MemoryError: throw std::bad_alloc();
    case ErrorKind::RuntimeError: break;
  }
  throw std::runtime_error(message);
}

}  // namespace bsp
