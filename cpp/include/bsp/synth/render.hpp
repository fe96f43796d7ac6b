// A tiny CPU ray caster for bsp-synth. The camera is static within a clip, so the street is
// ray-cast once per clip (render_background: RGB, CARLA semantic tag and depth per pixel),
// and each frame only re-casts the pixels inside the pedestrian's projected bounding box
// (render_bodies), depth-tested against the background, so parked cars and poles in front
// of the pedestrian occlude it. RGB and tags come from the same hit, so the segmentation is
// pixel-aligned with the video by construction.
//
// Pixel (i, j) covers u in [j, j + 1), v in [i, i + 1) of the CARLA projection
// (camera.hpp); its ray goes through (j + 0.5, i + 0.5). Depth is the camera-x distance
// (the same x the projection divides by); sky pixels have depth +inf.
//
// Everything is deterministic: each pixel is computed by the same code whatever the thread
// count, so the images are bitwise identical for 1..N threads.
#pragma once
#include <cstddef>
#include <cstdint>
#include <vector>

#include "bsp/geometry/camera.hpp"
#include "bsp/geometry/kinematics.hpp"

namespace bsp::render {

// Static scene geometry lives in a "road frame": s along the road, w across it (to the
// right, like CARLA's y), z up; `road` maps road-frame points to world points.
//
// Ground plane z = 0: the last band with w0 <= w < w1 (and, for dashed bands, inside a
// dash: fmod(s - phase, period) < on) gives the tag and colour. No band: tag 0, black.
struct GroundBand {
  double w0 = 0, w1 = 0;
  std::uint8_t tag = 0;
  Vec3 rgb = Vec3::Zero();  // 0..255
  double dash_period = 0, dash_on = 0, dash_phase = 0;  // period 0: solid
  double texture = 0;  // amplitude of the value noise (0..1)
};

// Surface patterns of boxes (purely visual; the tag is the box's).
enum class Pattern : int { Plain = 0, Windows = 1, Glass = 2, Tiles = 3 };

// Axis-aligned box in the road frame, [lo, hi].
struct Box {
  Vec3 lo = Vec3::Zero(), hi = Vec3::Zero();
  std::uint8_t tag = 0;
  Vec3 rgb = Vec3::Zero();
  Pattern pattern = Pattern::Plain;
  double texture = 0;
};

// Vertical cylinder (axis along z) centred at (s, w), z in [z0, z1], with a top cap.
struct Cylinder {
  double s = 0, w = 0, z0 = 0, z1 = 0, radius = 0;
  std::uint8_t tag = 0;
  Vec3 rgb = Vec3::Zero();
  double texture = 0;
};

struct Sphere {
  Vec3 centre = Vec3::Zero();
  double radius = 0;
  std::uint8_t tag = 0;
  Vec3 rgb = Vec3::Zero();
  double texture = 0;
};

struct Lighting {
  Vec3 sun = Vec3(0.3, 0.2, 0.93);  // world frame, towards the sun (normalised on use)
  double ambient = 0.45, diffuse = 0.6;
  Vec3 sky_zenith = Vec3(70, 130, 180), sky_horizon = Vec3(200, 215, 230);
  double fog_distance = 400;  // metres; colour fades to the horizon colour
};

struct Scene {
  Transform road;  // world-from-road
  std::vector<GroundBand> bands;
  std::vector<Box> boxes;
  std::vector<Cylinder> cylinders;
  std::vector<Sphere> spheres;
  Lighting light;
};

// A camera pose (world-from-camera, CARLA axes: x forward, y right, z up) and intrinsics.
struct Camera {
  Transform pose;
  Intrinsics k;
  int width() const { return static_cast<int>(k.width); }
  int height() const { return static_cast<int>(k.height); }
};

// Option checks (std::invalid_argument with the message bsp_fast shows); render_background
// and render_bodies run them first. A camera needs a positive image size and 0 < fov < 180;
// lighting a fog distance > 0 and a non-zero sun direction; a scene valid lighting and box
// patterns in 0..3 (boxes are named by row).
void check_camera(const Camera& cam);
void check_lighting(const Lighting& light);
void check_scene(const Scene& scene);

// Unnormalised ray direction through pixel centre (j + 0.5, i + 0.5), in camera axes:
// (1, y, z), so a hit at ray parameter t has camera-x depth t.
Vec3 pixel_direction(const Camera& cam, int i, int j);

// Ray-casts the static scene. Outputs (H, W, 3) RGB, (H, W) tags, (H, W) depth, all
// row-major. `threads` as in bsp::parallel_for (0 = default, 1 = inline).
void render_background(const Scene& scene, const Camera& cam, std::uint8_t* rgb,
                       std::uint8_t* tags, float* depth, int threads = 0);

// One body primitive: a capsule from a to b (a == b: a sphere) of `radius`, world frame.
struct Capsule {
  Vec3 a = Vec3::Zero(), b = Vec3::Zero();
  double radius = 0;
  Vec3 rgb = Vec3::Zero();
};

// Draws `frames` poses of the pedestrian (caps_per_frame capsules each, frame-major) over
// the background, tag 4 (Pedestrian) where a capsule is nearer than the background.
// Outputs (frames, H, W, 3) RGB, (frames, H, W) tags and visible[f] = 1 when frame f has
// at least one pedestrian pixel.
void render_bodies(const Camera& cam, const Lighting& light, const std::uint8_t* bg_rgb,
                   const std::uint8_t* bg_tags, const float* bg_depth, const Capsule* caps,
                   std::size_t caps_per_frame, std::size_t frames, std::uint8_t* rgb,
                   std::uint8_t* tags, std::uint8_t* visible, int threads = 0);

// visible[f] exactly as render_bodies computes it over render_background's images of
// `scene`, without drawing either: only the background pixels that some capsule's ray hits
// are cast (once per call), and a frame stops at its first pedestrian pixel. For the
// poses-only mode of bsp-synth, which needs the flag and no image.
void body_visibility(const Scene& scene, const Camera& cam, const Capsule* caps,
                     std::size_t caps_per_frame, std::size_t frames, std::uint8_t* visible,
                     int threads = 0);

}  // namespace bsp::render
