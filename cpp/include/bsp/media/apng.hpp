// Animated PNG: the segmentation writer (8-bit palette-indexed, pixel index = CARLA tag) and
// our own decoder. Both stream: memory is O(one frame), never O(clip).
#pragma once
#include <array>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

namespace bsp {

// CARLA 0.9.13 semantic tags 0..22 (docs/dataset-format.md, "3. Media") and their
// Cityscapes colours.
inline constexpr int kNumTags = 23;
extern const std::array<const char*, kNumTags> kTagNames;
extern const std::array<std::array<std::uint8_t, 3>, kNumTags> kCityscapesColors;
// 256 x RGB: the Cityscapes colours at their tag's index, black elsewhere.
std::vector<std::uint8_t> cityscapes_palette();

// Writes an 8-bit palette-indexed APNG (IHDR colour type 3, PLTE, acTL; frame 0 as
// fcTL+IDAT, later frames as fcTL+fdAT). Frames after the first hold only the bounding
// rectangle of the pixels that changed (dispose NONE, blend SOURCE). With drop_duplicates
// an identical consecutive frame is not stored; the previous frame's delay grows instead.
// acTL's frame count is patched at close(). The file is written to "<path>.tmp-<pid>-<n>"
// and renamed by close(); a writer destroyed without close() deletes it.
class ApngWriter {
 public:
  // `palette` holds 256 RGB triplets (768 bytes). `level` is libdeflate's level (1..12).
  ApngWriter(std::string path, int width, int height, const std::vector<std::uint8_t>& palette,
             double fps = 30, bool drop_duplicates = false, int level = 6);
  ~ApngWriter();
  ApngWriter(const ApngWriter&) = delete;
  ApngWriter& operator=(const ApngWriter&) = delete;

  // One frame of height*width palette indices, rows top to bottom.
  void write(const std::uint8_t* indices);
  // Writes the pending frame, patches acTL and renames into place. Idempotent.
  void close();

  std::int64_t frames_written() const;  // frames passed to write()
  std::int64_t frames_stored() const;   // APNG frames in the file (after dropping duplicates)
  int width() const;
  int height() const;
  const std::string& path() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// Our APNG decoder (also reads plain PNGs as one frame). Colour types 0 (grey), 2 (RGB),
// 3 (palette: returns the INDICES, i.e. the class tags), 4 (grey+alpha), 6 (RGBA); 8-bit,
// non-interlaced only. Frames are composited on a cached canvas with the fcTL dispose ops
// (NONE/BACKGROUND/PREVIOUS) and blend ops (SOURCE/OVER), so sequential reads are cheap.
// The file is read once at open: the chunk walk checks every CRC and the frame sequence.
// Damage found there does not stop the open: frames before the damaged one stay readable,
// reading it or a later one throws ApngError naming the frame, the chunk and the reason.
// Not thread-safe per object (read() takes a lock); use one reader per thread.
class ApngReader {
 public:
  explicit ApngReader(std::string path);
  ~ApngReader();
  ApngReader(const ApngReader&) = delete;
  ApngReader& operator=(const ApngReader&) = delete;

  std::int64_t frame_count() const;
  int width() const;
  int height() const;
  int channels() const;     // bytes per output pixel: 1 (indexed, grey), 2, 3 or 4
  int colour_type() const;  // PNG colour type of the file
  bool indexed() const;     // colour type 3: read() returns palette indices
  std::vector<std::uint8_t> palette() const;  // PLTE as RGB triplets (empty if none)
  std::vector<double> delays() const;         // seconds each frame is shown
  std::vector<std::uint8_t> dispose_ops() const;
  std::vector<std::uint8_t> blend_ops() const;
  // "frame K: reason" for the first frame the open found damaged (CRC, truncation, bad
  // fcTL, sequence error), or "" for an undamaged file.
  std::string damage() const;

  // Writes the composited frames `indices` (any order, repeats allowed) to `out`, which
  // holds indices.size() * height * width * channels bytes.
  void read(const std::vector<std::int64_t>& indices, std::uint8_t* out);

  // For each video frame k (shown at k / fps), the APNG frame on screen at that time by the
  // cumulative delays; -1 once the animation's total duration has passed.
  std::vector<std::int64_t> video_to_apng_frames(std::int64_t n_video_frames, double fps) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace bsp
