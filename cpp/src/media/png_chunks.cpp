// The PNG/APNG chunk walk: signature, CRC of every chunk, IHDR/PLTE/tRNS/acTL, fcTL and
// fdAT sequence numbers, and the table of frames with the file offsets of their zlib data.
#include <algorithm>
#include <cstring>

#include "bsp/common/errors.hpp"
#include "png.hpp"

namespace bsp::png {
namespace {

int channels_of(int colour_type) {
  switch (colour_type) {
    case 0: return 1;
    case 2: return 3;
    case 3: return 1;
    case 4: return 2;
    case 6: return 4;
    default: return 0;
  }
}

std::string chunk_name(const std::uint8_t* t) {
  std::string s;
  for (int i = 0; i < 4; ++i)
    s += (t[i] >= 32 && t[i] < 127) ? static_cast<char>(t[i]) : '?';
  return s;
}

struct Indexer : FileIndex {
  const std::string& path;
  const std::vector<std::uint8_t>& file;

  Indexer(const std::string& p, const std::vector<std::uint8_t>& f) : path(p), file(f) {}
  [[noreturn]] void fail(const std::string& what) const { throw ApngError(path + ": " + what); }
  void parse();
  bool handle_chunk(const std::uint8_t* type, const std::uint8_t* d, std::uint32_t len,
                    std::size_t at, std::uint32_t& seq, bool& seen_idat);
  void read_ihdr(const std::uint8_t* d, std::uint32_t len);
  void read_trns(const std::uint8_t* d, std::uint32_t len);
  void read_fctl(const std::uint8_t* d, std::uint32_t len, std::uint32_t& seq);
  void mark_bad(std::int64_t frame, const std::string& why);
  std::int64_t frame_of_next_data() const {
    return std::max<std::int64_t>(0, static_cast<std::int64_t>(frames.size()) - 1);
  }
};

void Indexer::mark_bad(std::int64_t frame, const std::string& why) {
  if (bad_frame < 0 || frame < bad_frame) {
    bad_frame = frame;
    bad_reason = why;
  }
}

void Indexer::read_ihdr(const std::uint8_t* d, std::uint32_t len) {
  if (len != 13) fail("IHDR has " + std::to_string(len) + " bytes, expected 13");
  width = get_u32(d);
  height = get_u32(d + 4);
  const int depth = d[8];
  colour_type = d[9];
  if (width == 0 || height == 0)
    fail("invalid image size " + std::to_string(width) + "x" + std::to_string(height));
  // Decompression bombs: a few bytes of header must not size a gigabyte canvas.
  if (width > kMaxSide || height > kMaxSide ||
      std::uint64_t{width} * height > kMaxPixels)
    fail("image size " + std::to_string(width) + "x" + std::to_string(height) +
         " exceeds the limit (" + std::to_string(kMaxSide) + " pixels a side, " +
         std::to_string(kMaxPixels) + " pixels in all)");
  if (channels_of(colour_type) == 0)
    fail("unsupported colour type " + std::to_string(colour_type));
  if (depth != 8)
    fail("unsupported bit depth " + std::to_string(depth) + " (only 8-bit PNGs are supported)");
  if (d[10] != 0 || d[11] != 0) fail("unknown compression or filter method in IHDR");
  if (d[12] != 0) fail("interlaced (Adam7) PNGs are not supported");
  channels = static_cast<std::size_t>(channels_of(colour_type));
}

void Indexer::read_trns(const std::uint8_t* d, std::uint32_t len) {
  if (colour_type == 3) {
    std::memcpy(palette_alpha, d, std::min<std::size_t>(len, 256));
    has_trns = true;
  } else if (colour_type == 0 || colour_type == 2) {
    if (len != 2 * channels) fail("tRNS has " + std::to_string(len) + " bytes");
    // An 8-bit image's samples fit the low byte; a key with a high byte never matches.
    has_key = true;
    for (std::size_t c = 0; c < channels; ++c) {
      key[c] = d[2 * c + 1];
      has_key = has_key && d[2 * c] == 0;
    }
  }
}

void Indexer::read_fctl(const std::uint8_t* d, std::uint32_t len, std::uint32_t& seq) {
  const auto f = static_cast<std::int64_t>(frames.size());
  if (len != 26) return mark_bad(f, "fcTL has " + std::to_string(len) + " bytes, expected 26");
  if (get_u32(d) != seq)
    return mark_bad(f, "fcTL sequence number " + std::to_string(get_u32(d)) + ", expected " +
                           std::to_string(seq));
  ++seq;
  FrameInfo fr;
  fr.w = get_u32(d + 4), fr.h = get_u32(d + 8);
  fr.x = get_u32(d + 12), fr.y = get_u32(d + 16);
  fr.delay_num = get_u16(d + 20), fr.delay_den = get_u16(d + 22);
  fr.dispose = d[24], fr.blend = d[25];
  if (fr.delay_den == 0) fr.delay_den = 100;  // APNG spec: 0 means 1/100 s
  frames.push_back(fr);
  if (fr.w == 0 || fr.h == 0 || fr.x >= width || fr.y >= height || fr.w > width - fr.x ||
      fr.h > height - fr.y)
    return mark_bad(f, "fcTL region " + std::to_string(fr.w) + "x" + std::to_string(fr.h) + "+" +
                           std::to_string(fr.x) + "+" + std::to_string(fr.y) +
                           " is outside the " + std::to_string(width) + "x" +
                           std::to_string(height) + " canvas");
  if (f == 0 && (fr.x || fr.y || fr.w != width || fr.h != height))
    return mark_bad(f, "the first fcTL must cover the whole canvas");
  if (fr.dispose > kDisposePrevious) return mark_bad(f, "unknown dispose_op " + std::to_string(fr.dispose));
  if (fr.blend > kBlendOver) return mark_bad(f, "unknown blend_op " + std::to_string(fr.blend));
}

// Returns true at IEND. Frame-level problems are recorded with mark_bad.
bool Indexer::handle_chunk(const std::uint8_t* type, const std::uint8_t* d,
                                    std::uint32_t len, std::size_t at, std::uint32_t& seq,
                                    bool& seen_idat) {
  auto is = [&](const char* t) { return std::memcmp(type, t, 4) == 0; };
  if (is("IHDR")) {
    // A second IHDR would change the canvas under frames already sized for the first one.
    if (width != 0)
      fail("frame " + std::to_string(frame_of_next_data()) + ": second IHDR chunk at byte " +
           std::to_string(at - 8) + " (a PNG has exactly one, first)");
    read_ihdr(d, len);
  } else if (is("PLTE")) {
    if (len % 3 || len == 0 || len > 768) fail("PLTE has " + std::to_string(len) + " bytes");
    palette.assign(d, d + len);
  } else if (is("tRNS")) {
    read_trns(d, len);
  } else if (is("acTL")) {
    if (len != 8) fail("acTL has " + std::to_string(len) + " bytes, expected 8");
    declared = get_u32(d);
    if (declared == 0) fail("acTL declares 0 frames");
    if (declared > kMaxFrames)
      fail("acTL declares " + std::to_string(declared) + " frames, more than the limit of " +
           std::to_string(kMaxFrames));
  } else if (is("fcTL")) {
    read_fctl(d, len, seq);
  } else if (is("IDAT")) {
    seen_idat = true;
    if (declared < 0 || frames.size() == 1) {
      if (frames.empty()) frames.emplace_back();  // plain PNG: the image is frame 0
      frames.back().data.emplace_back(at, len);
    } else if (!frames.empty()) {
      mark_bad(frame_of_next_data(), "IDAT after the first animation frame");
    }  // else: a default image that is not part of the animation (skipped)
  } else if (is("fdAT")) {
    const std::int64_t f = frame_of_next_data();
    if (len < 4 || frames.empty()) return mark_bad(f, "fdAT without a frame"), false;
    if (get_u32(d) != seq)
      return mark_bad(f, "fdAT sequence number " + std::to_string(get_u32(d)) +
                             ", expected " + std::to_string(seq)), false;
    ++seq;
    frames.back().data.emplace_back(at + 4, len - 4);
  } else if (is("IEND")) {
    return true;
  }
  return false;
}


// Walks the chunks once. Damage before the first frame's data makes the file unusable and
// throws; later damage is recorded against the frame it belongs to (see mark_bad).
void Indexer::parse() {
  const std::size_t size = file.size();
  if (size < 8 || std::memcmp(file.data(), kSignature, 8) != 0)
    fail(size == 0 ? "empty file" : "not a PNG file (bad signature)");
  std::uint32_t seq = 0;
  bool seen_idat = false, ended = false;
  std::size_t pos = 8;
  while (!ended && bad_frame < 0) {
    const bool headers_done = !frames.empty() || seen_idat;
    auto damage = [&](const std::string& why, bool starts_frame) {
      if (!headers_done) fail(why);
      mark_bad(starts_frame ? static_cast<std::int64_t>(frames.size()) : frame_of_next_data(), why);
    };
    if (pos + 8 > size) {
      damage("truncated file: it ends at byte " + std::to_string(size) + " before IEND", false);
      break;
    }
    const std::uint8_t* p = file.data() + pos;
    const std::uint32_t len = get_u32(p);
    const std::string name = chunk_name(p + 4);
    if (len > 0x7fffffffu || pos + 12 + len > size) {
      damage("truncated file: chunk " + name + " at byte " + std::to_string(pos) + " needs " +
                 std::to_string(12ull + len) + " bytes, the file has " + std::to_string(size - pos) +
                 " left",
             name == "fcTL");
      break;
    }
    if (get_u32(p + 8 + len) != chunk_crc(p + 4, p + 8, len)) {
      damage("bad CRC in chunk " + name + " at byte " + std::to_string(pos) + " (file corrupt)",
             name == "fcTL");
      break;
    }
    if (pos == 8 && name != "IHDR") fail("first chunk is " + name + ", expected IHDR");
    ended = handle_chunk(p + 4, p + 8, len, pos + 8, seq, seen_idat);
    pos += 12 + std::size_t{len};
  }
  if (!seen_idat && frames.empty()) fail("no image data (IDAT) before the damage or the end");
  if (colour_type == 3 && palette.empty()) fail("palette image without a PLTE chunk");
  if (declared < 0) {  // plain PNG: one full frame
    frames.resize(1);
    frames[0].w = width, frames[0].h = height;
    frames[0].delay_num = 0;
    declared = 1;
  }
  if (bad_frame < 0 && static_cast<std::int64_t>(frames.size()) != declared)
    fail("acTL declares " + std::to_string(declared) + " frames but the file holds " +
         std::to_string(frames.size()));
  for (std::size_t f = 0; f < frames.size(); ++f)
    if (frames[f].data.empty() && (bad_frame < 0 || static_cast<std::int64_t>(f) < bad_frame))
      mark_bad(static_cast<std::int64_t>(f), "no image data after its fcTL");
}

}  // namespace

FileIndex index_png(const std::vector<std::uint8_t>& file, const std::string& path) {
  Indexer ix(path, file);
  ix.parse();
  return FileIndex(std::move(static_cast<FileIndex&>(ix)));
}

}  // namespace bsp::png
