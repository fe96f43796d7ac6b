// Decoding one recording's block of the frame table: the segmentation first (it decides
// the crop), then the video, converting only the crop region of each frame to RGB.
#include <algorithm>
#include <cstring>

#include "bsp/media/apng.hpp"
#include "bsp/media/video.hpp"
#include "convert_internal.hpp"

namespace bsp::detail {
namespace {

constexpr int J = 26;

MediaBlock make_block(std::size_t frames, int S) {
  MediaBlock b;
  b.frames = frames;
  for (const FrameColumn& c : frame_columns(S)) {
    b.bytes.push_back(c.bytes);
    b.cols.emplace_back(frames * c.bytes);
  }
  return b;
}

// Statistics, crop boxes and mask crops of every frame from the segmentation APNG.
void segmentation_pass(const PoseTable& t, const std::size_t* rows, const std::string& path,
                       ApngReader& seg, double fps, int S, MediaBlock& b) {
  const int W = seg.width(), H = seg.height();
  const auto map = seg.video_to_apng_frames(t.frame_idx[rows[b.frames - 1]] + 1, fps);
  std::vector<std::uint8_t> tags(static_cast<std::size_t>(W) * H);
  std::int64_t shown = -1;  // APNG frame now in `tags`
  for (std::size_t i = 0; i < b.frames; ++i) {
    const std::int64_t k = t.frame_idx[rows[i]], a = map[static_cast<std::size_t>(k)];
    if (a < 0)
      throw ApngError(path + ": video frame " + std::to_string(k) +
                      " is shown after the end of the animation (" +
                      std::to_string(seg.frame_count()) + " frames)");
    if (a != shown) seg.read({a}, tags.data()), shown = a;
    const FrameMedia m = frame_media(tags.data(), W, H, &t.pose_camera[rows[i] * J * 2]);
    std::memcpy(b.at<float>(kColCropBox, i), m.crop_box.data(), sizeof m.crop_box);
    std::memcpy(b.at<std::uint8_t>(kColJointVisible, i), m.joint_visible.data(), J);
    std::memcpy(b.at<std::int32_t>(kColMaskBbox, i), m.mask_bbox.data(), sizeof m.mask_bbox);
    *b.at<std::int64_t>(kColPixels, i) = m.visible_pixels;
    *b.at<std::int64_t>(kColFrameIdx, i) = k;
    crop_resize(tags.data(), 0, 0, W, H, 1, m.crop_box, S, true, b.at<std::uint8_t>(kColMask, i));
  }
}

// RGB crops: each frame's crop box clipped to the picture is all that gets converted.
void video_pass(const PoseTable& t, const std::size_t* rows, VideoReader& video, int S,
                MediaBlock& b, ConvertProgress* progress) {
  const int W = video.width(), H = video.height();
  std::vector<std::uint8_t> roi;
  for (std::size_t i = 0; i < b.frames; ++i) {
    std::array<float, 4> box;
    std::memcpy(box.data(), b.at<float>(kColCropBox, i), sizeof box);
    const int x0 = std::max(0, static_cast<int>(box[0])), y0 = std::max(0, static_cast<int>(box[1]));
    const int x1 = std::min(W, static_cast<int>(box[2])), y1 = std::min(H, static_cast<int>(box[3]));
    std::uint8_t* out = b.at<std::uint8_t>(kColRgb, i);
    if (x1 <= x0 || y1 <= y0) {  // the crop misses the picture: nothing to decode
      crop_resize(nullptr, 0, 0, 0, 0, 3, box, S, false, out);
      if (progress) ++progress->done;
      continue;
    }
    roi.resize(static_cast<std::size_t>(x1 - x0) * (y1 - y0) * 3);
    video.read({t.frame_idx[rows[i]]}, roi.data(), Crop{x0, y0, x1 - x0, y1 - y0});
    crop_resize(roi.data(), x0, y0, x1 - x0, y1 - y0, 3, box, S, false, out);
    if (progress) ++progress->done;
  }
}

}  // namespace

std::vector<FrameColumn> frame_columns(int crop_size) {
  const auto S = static_cast<hsize_t>(crop_size);
  const std::size_t s = static_cast<std::size_t>(crop_size);
  return {{"frames/rgb", h5::Type::U8, {S, S, 3}, s * s * 3},
          {"frames/mask", h5::Type::U8, {S, S}, s * s},
          {"frames/crop_box", h5::Type::F32, {4}, 16},
          {"frames/joint_visible", h5::Type::U8, {J}, J},
          {"frames/mask_bbox", h5::Type::I32, {4}, 16},
          {"frames/visible_pixels", h5::Type::I64, {}, 8},
          {"frames/frame_idx", h5::Type::I64, {}, 8}};
}

MediaBlock decode_block(const PoseTable& t, const FrameTable& table, std::size_t block,
                        const MediaFiles& files, int crop_size, ConvertProgress* progress) {
  const std::size_t first = table.begin[block];
  MediaBlock b = make_block(table.begin[block + 1] - first, crop_size);
  b.failure.recording = table.recordings[block];
  const std::size_t* rows = &table.rows[first];
  try {
    b.failure.path = files.video;
    VideoReader video(files.video, 1);
    b.failure.path = files.segmentation;
    ApngReader seg(files.segmentation);
    segmentation_pass(t, rows, files.segmentation, seg, video.fps(), crop_size, b);
    b.failure.path = files.video;
    video_pass(t, rows, video, crop_size, b, progress);
  } catch (const std::exception& e) {
    b.failure.reason = e.what();
    b.failure.error = std::current_exception();
  } catch (...) {
    b.failure.reason = "unknown error";
    b.failure.error = std::current_exception();
  }
  return b;
}

}  // namespace bsp::detail
