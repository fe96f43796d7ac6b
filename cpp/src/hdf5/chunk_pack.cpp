// Packing a chunk as libhdf5's shuffle + deflate filters store it (h5.hpp, ChunkPacker),
// so that the conversion can compress chunks in parallel: libhdf5's own filter pipeline
// runs on the one thread that may call libhdf5. Only libdeflate here, no libhdf5 call.
#include <libdeflate.h>

#include <new>

#include "hdf5/h5.hpp"

namespace bsp::h5 {

ChunkPacker::ChunkPacker(int level) : compressor_(libdeflate_alloc_compressor(level)) {
  if (!compressor_) throw std::bad_alloc();
}

ChunkPacker::~ChunkPacker() { libdeflate_free_compressor(compressor_); }

void ChunkPacker::pack(const void* data, std::size_t bytes, std::size_t elem,
                       std::vector<std::uint8_t>& out) {
  // H5Z shuffle: byte j of element i goes to j * count + i; a tail shorter than one
  // element stays as it is (none here: chunks hold whole elements).
  const auto* in = static_cast<const std::uint8_t*>(data);
  const std::uint8_t* plain = in;
  if (elem > 1) {
    shuffled_.resize(bytes);
    const std::size_t count = bytes / elem;
    for (std::size_t j = 0; j < elem; ++j)
      for (std::size_t i = 0; i < count; ++i) shuffled_[j * count + i] = in[i * elem + j];
    for (std::size_t k = count * elem; k < bytes; ++k) shuffled_[k] = in[k];
    plain = shuffled_.data();
  }
  // H5Z deflate: a zlib stream (header, deflate, Adler-32). The bound makes it succeed.
  out.resize(libdeflate_zlib_compress_bound(compressor_, bytes));
  const std::size_t n = libdeflate_zlib_compress(compressor_, plain, bytes, out.data(), out.size());
  if (n == 0) throw Hdf5Error("internal: a chunk did not fit libdeflate's bound");
  out.resize(n);
}

}  // namespace bsp::h5
