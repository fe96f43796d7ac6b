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

MediaBlock make_block(std::size_t frames, const MediaOptions& o) {
  MediaBlock b;
  b.frames = frames;
  for (const FrameColumn& c : frame_columns(o)) {
    b.bytes.push_back(c.bytes);
    b.cols.emplace_back(frames * c.bytes);
  }
  return b;
}

// Statistics, crop boxes and mask crops of every frame from the segmentation APNG.
void segmentation_pass(const PoseTable& t, const std::size_t* rows, const std::string& path,
                       ApngReader& seg, double fps, const MediaOptions& o, MediaBlock& b) {
  const int S = o.crop_size;
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
    const FrameMedia m = frame_media(tags.data(), W, H, &t.pose_camera[rows[i] * J * 2], o.crop_box);
    std::memcpy(b.at<float>(kColCropBox, i), m.crop_box.data(), sizeof m.crop_box);
    std::memcpy(b.at<std::uint8_t>(kColJointVisible, i), m.joint_visible.data(), J);
    std::memcpy(b.at<std::int32_t>(kColMaskBbox, i), m.mask_bbox.data(), sizeof m.mask_bbox);
    *b.at<std::int64_t>(kColPixels, i) = m.visible_pixels;
    *b.at<std::int64_t>(kColFrameIdx, i) = k;
    if (o.crop_context > 1) {
      const std::array<float, 4> wide = context_box(m.crop_box, o.crop_context);
      std::memcpy(b.at<float>(kColContextBox, i), wide.data(), sizeof wide);
    }
    // no crop: the block's columns stay zero (RGB black, tag 0)
    if (m.has_crop())
      crop_resize(tags.data(), 0, 0, W, H, 1, m.crop_box, S, true, b.at<std::uint8_t>(kColMask, i));
  }
}

// Cuts `box` (and `wide`, the context box, unless null) out of video frame k, converting
// only the part of the picture they cover.
void crop_video(VideoReader& video, std::int64_t k, const std::array<float, 4>& box, int S,
                std::uint8_t* out, const std::array<float, 4>* wide, int Sc, std::uint8_t* wide_out,
                std::vector<std::uint8_t>& roi) {
  const int W = video.width(), H = video.height();
  const std::array<float, 4>& outer = wide ? *wide : box;
  const int x0 = std::max(0, static_cast<int>(outer[0])), y0 = std::max(0, static_cast<int>(outer[1]));
  const int x1 = std::min(W, static_cast<int>(outer[2])), y1 = std::min(H, static_cast<int>(outer[3]));
  if (x1 <= x0 || y1 <= y0) {  // the crop misses the picture: nothing to decode
    crop_resize(nullptr, 0, 0, 0, 0, 3, box, S, false, out);
    if (wide) crop_resize(nullptr, 0, 0, 0, 0, 3, *wide, Sc, false, wide_out);
    return;
  }
  roi.resize(static_cast<std::size_t>(x1 - x0) * (y1 - y0) * 3);
  video.read({k}, roi.data(), Crop{x0, y0, x1 - x0, y1 - y0});
  crop_resize(roi.data(), x0, y0, x1 - x0, y1 - y0, 3, box, S, false, out);
  if (wide) crop_resize(roi.data(), x0, y0, x1 - x0, y1 - y0, 3, *wide, Sc, false, wide_out);
}

// RGB crops: each frame's crop box (or context box) clipped to the picture is all that
// gets converted. A frame without a crop stays zero.
void video_pass(const PoseTable& t, const std::size_t* rows, VideoReader& video,
                const MediaOptions& o, MediaBlock& b, ConvertProgress* progress) {
  const bool context = o.crop_context > 1;
  const int Sc = context ? context_size(o.crop_size, o.crop_context) : 0;
  std::vector<std::uint8_t> roi;
  for (std::size_t i = 0; i < b.frames; ++i) {
    std::array<float, 4> box, wide;
    std::memcpy(box.data(), b.at<float>(kColCropBox, i), sizeof box);
    if (context) std::memcpy(wide.data(), b.at<float>(kColContextBox, i), sizeof wide);
    if (box[0] == box[0])
      crop_video(video, t.frame_idx[rows[i]], box, o.crop_size, b.at<std::uint8_t>(kColRgb, i),
                 context ? &wide : nullptr, Sc,
                 context ? b.at<std::uint8_t>(kColContextRgb, i) : nullptr, roi);
    if (progress) ++progress->done;
  }
}

}  // namespace

std::vector<FrameColumn> frame_columns(const MediaOptions& o) {
  const auto S = static_cast<hsize_t>(o.crop_size);
  const std::size_t s = static_cast<std::size_t>(o.crop_size);
  std::vector<FrameColumn> c = {{"frames/rgb", h5::Type::U8, {S, S, 3}, s * s * 3},
                                {"frames/mask", h5::Type::U8, {S, S}, s * s},
                                {"frames/crop_box", h5::Type::F32, {4}, 16},
                                {"frames/joint_visible", h5::Type::U8, {J}, J},
                                {"frames/mask_bbox", h5::Type::I32, {4}, 16},
                                {"frames/visible_pixels", h5::Type::I64, {}, 8},
                                {"frames/frame_idx", h5::Type::I64, {}, 8}};
  if (o.crop_context > 1) {
    const int n = context_size(o.crop_size, o.crop_context);
    const auto C = static_cast<hsize_t>(n);
    const std::size_t cs = static_cast<std::size_t>(n);
    c.push_back({"frames/context_rgb", h5::Type::U8, {C, C, 3}, cs * cs * 3});
    c.push_back({"frames/context_box", h5::Type::F32, {4}, 16});
  }
  return c;
}

MediaBlock decode_block(const PoseTable& t, const FrameTable& table, std::size_t block,
                        const MediaFiles& files, const MediaOptions& o, ConvertProgress* progress) {
  const std::size_t first = table.begin[block];
  MediaBlock b = make_block(table.begin[block + 1] - first, o);
  b.failure.recording = table.recordings[block];
  const std::size_t* rows = &table.rows[first];
  try {
    b.failure.path = files.video;
    VideoReader video(files.video, 1);
    b.failure.path = files.segmentation;
    ApngReader seg(files.segmentation);
    segmentation_pass(t, rows, files.segmentation, seg, video.fps(), o, b);
    b.failure.path = files.video;
    video_pass(t, rows, video, o, b, progress);
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
