// Per-frame pedestrian maths of the media conversion: the tag-4 mask statistics, joint
// visibility, the square crop box, and cutting + resizing a crop (OpenCV imgproc).
#include <algorithm>
#include <cmath>
#include <cstring>
#include <stdexcept>
#include <string>
#include <opencv2/imgproc.hpp>

#include "bsp/common/errors.hpp"
#include "bsp/conversion/convert.hpp"

namespace bsp {
namespace {

constexpr int J = 26;

// Tag-4 pixel count and bounding box [u0, v0, u1, v1) of a whole frame.
void mask_stats(const std::uint8_t* tags, int width, int height, FrameMedia& m) {
  int u0 = width, v0 = height, u1 = -1, v1 = -1;
  std::int64_t count = 0;
  for (int y = 0; y < height; ++y) {
    const std::uint8_t* row = tags + static_cast<std::size_t>(y) * width;
    int n = 0;
    for (int x = 0; x < width; ++x) n += row[x] == kPedestrianTag;  // vectorises
    if (n == 0) continue;
    count += n;
    const auto* first = static_cast<const std::uint8_t*>(std::memchr(row, kPedestrianTag, width));
    int last = width - 1;
    while (row[last] != kPedestrianTag) --last;
    u0 = std::min(u0, static_cast<int>(first - row)), u1 = std::max(u1, last + 1);
    v0 = std::min(v0, y), v1 = y + 1;
  }
  m.visible_pixels = count;
  if (count) m.mask_bbox = {u0, v0, u1, v1};
}

bool finite_joint(const float* uv, int j) {
  return std::isfinite(uv[2 * j]) && std::isfinite(uv[2 * j + 1]);
}

// Any tag-4 pixel within kVisibilityRadius of the joint's rounded pixel.
bool joint_visible(const std::uint8_t* tags, int width, int height, double u, double v) {
  constexpr int r = kVisibilityRadius;
  const double cu = std::floor(u + 0.5), cv = std::floor(v + 0.5);
  if (cu < -r || cv < -r || cu >= width + r || cv >= height + r) return false;
  const int x0 = static_cast<int>(cu), y0 = static_cast<int>(cv);
  for (int dy = -r; dy <= r; ++dy)
    for (int dx = -r; dx <= r; ++dx) {
      const int x = x0 + dx, y = y0 + dy;
      if (dx * dx + dy * dy > r * r || x < 0 || y < 0 || x >= width || y >= height) continue;
      if (tags[static_cast<std::size_t>(y) * width + x] == kPedestrianTag) return true;
    }
  return false;
}

// Square box around the centre of the policy's box, integer edges (NaN: no crop).
std::array<float, 4> crop_box(const float* uv, const FrameMedia& m, int width, int height,
                              CropBoxPolicy policy) {
  double lo_u = INFINITY, lo_v = INFINITY, hi_u = -INFINITY, hi_v = -INFINITY;
  const bool joints = policy != CropBoxPolicy::mask;
  const bool mask = policy != CropBoxPolicy::joints;
  if (policy == CropBoxPolicy::mask && !m.visible_pixels) return {NAN, NAN, NAN, NAN};
  for (int j = 0; joints && j < J; ++j) {
    if (!finite_joint(uv, j)) continue;
    lo_u = std::min<double>(lo_u, uv[2 * j]), hi_u = std::max<double>(hi_u, uv[2 * j]);
    lo_v = std::min<double>(lo_v, uv[2 * j + 1]), hi_v = std::max<double>(hi_v, uv[2 * j + 1]);
  }
  if (mask && m.visible_pixels) {
    lo_u = std::min<double>(lo_u, m.mask_bbox[0]), lo_v = std::min<double>(lo_v, m.mask_bbox[1]);
    hi_u = std::max<double>(hi_u, m.mask_bbox[2]), hi_v = std::max<double>(hi_v, m.mask_bbox[3]);
  }
  if (!(lo_u <= hi_u)) lo_u = hi_u = width / 2.0, lo_v = hi_v = height / 2.0;  // nothing seen
  const double extent = std::max(hi_u - lo_u, hi_v - lo_v);
  // The epsilon keeps 1.2 * 10 = 12.000000000000002 at 12.
  const double side = std::max<double>(kCropMinSize, std::ceil(kCropScale * extent - 1e-9));
  const double u0 = std::floor((lo_u + hi_u) / 2 - side / 2 + 0.5);
  const double v0 = std::floor((lo_v + hi_v) / 2 - side / 2 + 0.5);
  return {static_cast<float>(u0), static_cast<float>(v0), static_cast<float>(u0 + side),
          static_cast<float>(v0 + side)};
}

}  // namespace

const char* crop_box_name(CropBoxPolicy p) {
  switch (p) {
    case CropBoxPolicy::mask: return "mask";
    case CropBoxPolicy::mask_joints: return "mask+joints";
    case CropBoxPolicy::joints: return "joints";
  }
  throw std::invalid_argument("unknown crop box policy");
}

CropBoxPolicy crop_box_policy(const std::string& name) {
  for (CropBoxPolicy p : {CropBoxPolicy::mask, CropBoxPolicy::mask_joints, CropBoxPolicy::joints})
    if (name == crop_box_name(p)) return p;
  throw std::invalid_argument("crop box must be one of mask, mask+joints, joints, got '" + name + "'");
}

std::array<float, 4> context_box(const std::array<float, 4>& box, double context) {
  const double side = box[2] - box[0];
  const double wide = std::ceil(context * side - 1e-9);
  const double u0 = box[0] - std::floor((wide - side) / 2), v0 = box[1] - std::floor((wide - side) / 2);
  return {static_cast<float>(u0), static_cast<float>(v0), static_cast<float>(u0 + wide),
          static_cast<float>(v0 + wide)};
}

int context_size(int crop_size, double context) {
  return static_cast<int>(std::ceil(context * crop_size - 1e-9));
}

FrameMedia frame_media(const std::uint8_t* tags, int width, int height, const float* uv,
                       CropBoxPolicy policy) {
  FrameMedia m;
  mask_stats(tags, width, height, m);
  for (int j = 0; j < J; ++j)
    m.joint_visible[j] = m.visible_pixels && finite_joint(uv, j) &&
                         joint_visible(tags, width, height, uv[2 * j], uv[2 * j + 1]);
  m.crop_box = crop_box(uv, m, width, height, policy);
  return m;
}

void crop_resize(const std::uint8_t* roi, int roi_x, int roi_y, int roi_width, int roi_height,
                 int channels, const std::array<float, 4>& box, int size, bool nearest,
                 std::uint8_t* out) {
  const int x0 = static_cast<int>(box[0]), y0 = static_cast<int>(box[1]);
  const int side = static_cast<int>(box[2] - box[0]);
  if (side <= 0 || static_cast<int>(box[3] - box[1]) != side)
    throw Error("crop box is not a non-empty square");
  const int type = CV_8UC(channels);
  cv::Mat canvas(side, side, type, cv::Scalar::all(0));
  const int ix0 = std::max(x0, roi_x), iy0 = std::max(y0, roi_y);
  const int ix1 = std::min(x0 + side, roi_x + roi_width), iy1 = std::min(y0 + side, roi_y + roi_height);
  if (ix1 > ix0 && iy1 > iy0) {
    const cv::Mat src(roi_height, roi_width, type, const_cast<std::uint8_t*>(roi));
    src(cv::Rect(ix0 - roi_x, iy0 - roi_y, ix1 - ix0, iy1 - iy0))
        .copyTo(canvas(cv::Rect(ix0 - x0, iy0 - y0, ix1 - ix0, iy1 - iy0)));
  }
  cv::Mat dst(size, size, type, out);
  cv::resize(canvas, dst, dst.size(), 0, 0, nearest ? cv::INTER_NEAREST : cv::INTER_AREA);
  if (dst.data != out) throw Error("internal: cv::resize reallocated the crop");
}

}  // namespace bsp
