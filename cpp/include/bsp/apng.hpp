// Animated PNG: the segmentation writer (8-bit palette-indexed, pixel index = CARLA tag) and
// our own decoder. Both stream: memory is O(one frame), never O(clip).
#pragma once
#include <array>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

namespace bsp {

// CARLA 0.9.13 semantic tags 0..22 (SPEC section 1) and their Cityscapes colours.
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

}  // namespace bsp
