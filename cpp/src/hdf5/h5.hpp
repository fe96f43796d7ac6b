// Thin RAII layer over the libhdf5 C API: every call that can fail is checked once here and
// turned into bsp::Hdf5Error naming the file, the object and HDF5's own reason.
// Note: h5py wheels bundle another libhdf5; never pass these handles to Python.
// Private to bsp_core (with libhdf5's headers): no public header exposes HDF5.
#pragma once
#include <hdf5.h>

#include <cstdint>
#include <string>
#include <utility>
#include <vector>

#include "bsp/common/errors.hpp"

struct libdeflate_compressor;  // <libdeflate.h>

namespace bsp::h5 {

// Owns one hid_t and closes it with the right H5*close function.
class Handle {
 public:
  using Closer = herr_t (*)(hid_t);
  Handle() = default;
  Handle(hid_t id, Closer closer) : id_(id), closer_(closer) {}
  Handle(Handle&& o) noexcept : id_(std::exchange(o.id_, -1)), closer_(o.closer_) {}
  Handle& operator=(Handle&& o) noexcept {
    if (this != &o) reset(), id_ = std::exchange(o.id_, -1), closer_ = o.closer_;
    return *this;
  }
  Handle(const Handle&) = delete;
  Handle& operator=(const Handle&) = delete;
  ~Handle() { reset(); }
  hid_t id() const { return id_; }
  void reset() noexcept {
    if (id_ >= 0 && closer_) closer_(id_);
    id_ = -1;
  }

 private:
  hid_t id_ = -1;
  Closer closer_ = nullptr;
};

// Compression of chunked datasets: none, or byte-shuffle + deflate at `level`.
struct Compression {
  bool deflate = false;
  int level = 1;
};

// One chunk of a dataset created with Compression{true, level}, packed as libhdf5's filter
// pipeline stores it: bytes shuffled by element size (H5Z shuffle), then deflated in zlib's
// format (libdeflate at the same level: the bytes differ from zlib's, the data read back
// do not). No libhdf5 call and no shared state: chunks are packed on worker threads, in
// parallel, and written by Group::write_chunk on the thread that owns the file.
class ChunkPacker {
 public:
  explicit ChunkPacker(int level);
  ~ChunkPacker();
  ChunkPacker(const ChunkPacker&) = delete;
  ChunkPacker& operator=(const ChunkPacker&) = delete;
  // `bytes` of elements of `elem` bytes -> out (resized to the packed size).
  void pack(const void* data, std::size_t bytes, std::size_t elem, std::vector<std::uint8_t>& out);

 private:
  ::libdeflate_compressor* compressor_;
  std::vector<std::uint8_t> shuffled_;
};

// A typed element for datasets and attributes.
enum class Type { F32, F64, I32, I64, U8, Bool, Str };

class File;

class Group {
 public:
  Group(Handle h, std::string path, std::string file) : h_(std::move(h)), path_(std::move(path)), file_(std::move(file)) {}
  Group create_group(const std::string& name) const;
  // Creates a chunked dataset of `shape`; the first dim is the clip/frame axis and chunks hold
  // `chunk_rows` of it. Returns the dataset handle for write_rows.
  Handle create_dataset(const std::string& name, Type type, const std::vector<hsize_t>& shape,
                        hsize_t chunk_rows, const Compression& c) const;
  // Writes rows [row0, row0 + rows) of a dataset created above from a C-contiguous buffer.
  void write_rows(const Handle& ds, const std::string& name, Type type,
                  const std::vector<hsize_t>& shape, hsize_t row0, hsize_t rows,
                  const void* data) const;
  // Writes one whole chunk as stored, i.e. packed by ChunkPacker for a dataset created with
  // Compression{true, level} (H5Dwrite_chunk, all filters applied); `offset` is the chunk's
  // first element in each dimension.
  void write_chunk(const Handle& ds, const std::string& name, const std::vector<hsize_t>& offset,
                   const std::vector<std::uint8_t>& packed) const;
  // Variable-length UTF-8 string dataset (N,), written at once.
  void write_strings(const std::string& name, const std::vector<std::string>& values) const;

  void attr(const std::string& name, const std::string& value) const;
  void attr(const std::string& name, double value) const;
  void attr(const std::string& name, std::int64_t value) const;
  void attr(const std::string& name, const std::vector<std::string>& values) const;
  void attr(const std::string& name, const std::vector<std::int64_t>& values) const;
  hid_t id() const { return h_.id(); }
  const std::string& path() const { return path_; }

 private:
  std::string where(const std::string& name) const;
  // Creates attribute `name` of `type` over `space` and writes `data` into it.
  void write_attr(const std::string& name, hid_t type, const Handle& space,
                  const void* data) const;
  Handle h_;
  std::string path_, file_;
};


class File {
 public:
  // Creates (truncates) `path`. The caller writes to a temporary name and renames.
  static File create(const std::string& path);
  Group root() const;
  void close();  // flushes; errors surface here rather than in a destructor
  const std::string& path() const { return path_; }

 private:
  Handle h_;
  std::string path_;
};

}  // namespace bsp::h5
