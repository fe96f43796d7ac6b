// bsp-synth's C++ half: the ray caster (bsp/synth/render.hpp) on hand-made scenes, and the
// animation import (bsp/synth/motion.hpp) of a tiny BVH written here, read via assimp.
#include <doctest/doctest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <limits>
#include <string>
#include <vector>

#include "bsp/common/errors.hpp"
#include "bsp/synth/motion.hpp"
#include "bsp/synth/render.hpp"
#include "synth/render_internal.hpp"  // white-box: capsule hits, noise
#include "testing.hpp"

using namespace bsp;
using namespace bsp::render;

namespace {
// A level camera at height 1 m looking along +x, 64 x 32 pixels, 90 degrees (f = 32).
Camera level_camera() {
  Camera cam;
  cam.pose.t = Vec3(0, 0, 1);
  cam.k = Intrinsics{64, 32, 90.0};
  return cam;
}

Scene ground_only() {
  Scene sc;
  GroundBand all;
  all.w0 = -1e9, all.w1 = 1e9, all.tag = 7, all.rgb = Vec3(100, 100, 100);
  sc.bands.push_back(all);
  return sc;
}

struct Images {
  std::vector<std::uint8_t> rgb, tags;
  std::vector<float> depth;
};

Images background(const Scene& sc, const Camera& cam, int threads) {
  const std::size_t n = static_cast<std::size_t>(cam.width()) * cam.height();
  Images im{std::vector<std::uint8_t>(3 * n), std::vector<std::uint8_t>(n),
            std::vector<float>(n)};
  render_background(sc, cam, im.rgb.data(), im.tags.data(), im.depth.data(), threads);
  return im;
}

// Root + one child; the child turns about Z by 0, 30, 60, 90 degrees over 4 frames at 10 fps.
// In the test case's own directory: ctest runs the cases as parallel processes, and one
// case's clean-up must not delete the file another is reading (it did, with one /tmp name).
std::string write_bvh(const bsp::testing::TempDir& tmp) {
  const std::string path = tmp.path("motion.bvh");
  std::ofstream out(path);
  out << "HIERARCHY\nROOT Hips\n{\n  OFFSET 0 0 0\n"
         "  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation\n"
         "  JOINT LeftUpLeg\n  {\n    OFFSET 10 0 0\n    CHANNELS 3 Zrotation Xrotation "
         "Yrotation\n    End Site\n    {\n      OFFSET 0 -40 0\n    }\n  }\n}\n"
         "MOTION\nFrames: 4\nFrame Time: 0.1\n";
  for (int f = 0; f < 4; ++f) out << "0 90 " << f * 2 << " 0 0 0 " << 30 * f << " 0 0\n";
  return path;
}
}  // namespace

TEST_CASE("capsule intersection: hand-computed hits") {
  const Vec3 o(0, 0, 0), d(1, 0, 0);
  // Body: a vertical capsule at x = 5, radius 0.5 -> hit at 4.5.
  CHECK(intersect_capsule(o, d, Vec3(5, 0, -1), Vec3(5, 0, 1), 0.5) == doctest::Approx(4.5));
  // End cap: the ray passes above the segment's top end: sphere of radius 0.5 at (5,0,1),
  // ray at z = 1.3 -> depth 5 - sqrt(0.25 - 0.09) = 4.6.
  CHECK(intersect_capsule(Vec3(0, 0, 1.3), d, Vec3(5, 0, -1), Vec3(5, 0, 1), 0.5) ==
        doctest::Approx(4.6));
  // Sphere (a == b) and a ray along the axis of a capsule.
  CHECK(intersect_capsule(o, d, Vec3(3, 0, 0), Vec3(3, 0, 0), 1.0) == doctest::Approx(2.0));
  CHECK(intersect_capsule(o, d, Vec3(4, 0, 0), Vec3(8, 0, 0), 1.0) == doctest::Approx(3.0));
  // Misses: beside it, and behind the origin.
  CHECK(intersect_capsule(o, d, Vec3(5, 2, -1), Vec3(5, 2, 1), 0.5) < 0);
  CHECK(intersect_capsule(o, d, Vec3(-5, 0, -1), Vec3(-5, 0, 1), 0.5) < 0);
}

TEST_CASE("value noise is deterministic and bounded") {
  double lo = 1, hi = -1;
  for (int i = 0; i < 2000; ++i) {
    const Vec3 p(i * 0.37 - 300, i * 0.11 + 5, -i * 0.05);
    const double v = value_noise(p);
    CHECK(v == value_noise(p));
    lo = std::min(lo, v), hi = std::max(hi, v);
  }
  CHECK(lo >= -1.0);
  CHECK(hi <= 1.0);
  CHECK(hi - lo > 0.5);  // it actually varies
  CHECK(value_noise(Vec3(2, 3, 4)) == doctest::Approx(value_noise(Vec3(2, 3, 4) + Vec3(0, 0, 0))));
}

TEST_CASE("background: ground depth and sky follow the projection") {
  const Camera cam = level_camera();
  const Images im = background(ground_only(), cam, 1);
  const double f = cam.k.focal();
  CHECK(f == doctest::Approx(32.0));
  for (int i = 0; i < 32; ++i) {
    const std::size_t px = static_cast<std::size_t>(i) * 64 + 10;
    const double dz = (i + 0.5 - 16) / f;  // downward slope of the row's ray
    if (dz > 0) {
      CHECK(im.tags[px] == 7);
      CHECK(im.depth[px] == doctest::Approx(1.0 / dz).epsilon(1e-5));  // camera-x depth
    } else {
      CHECK(im.tags[px] == 13);  // sky above the horizon
      CHECK(std::isinf(im.depth[px]));
    }
  }
}

TEST_CASE("background: nearest primitive wins and bands select tags") {
  Scene sc = ground_only();
  Box wall;
  wall.lo = Vec3(10, -50, 0), wall.hi = Vec3(11, 50, 20), wall.tag = 1;
  wall.rgb = Vec3(200, 0, 0);
  sc.boxes.push_back(wall);
  Cylinder pole;
  pole.s = 5, pole.w = 0, pole.z0 = 0, pole.z1 = 10, pole.radius = 0.25, pole.tag = 5;
  sc.cylinders.push_back(pole);
  GroundBand line;
  line.w0 = 1.0, line.w1 = 1.5, line.tag = 6, line.rgb = Vec3(255, 255, 255);
  sc.bands.push_back(line);
  const Camera cam = level_camera();
  const Images im = background(sc, cam, 1);
  // Column 32 looks along y = (32.5 - 32) / 32 -> the pole (radius 0.25 at x = 5) is hit.
  const std::size_t centre = 10 * 64 + 32;
  CHECK(im.tags[centre] == 5);
  CHECK(im.depth[centre] < 5.0);
  CHECK(im.depth[centre] > 4.7);
  // Column 60 misses the pole and hits the wall's face x = 10.
  const std::size_t side = 10 * 64 + 60;
  CHECK(im.tags[side] == 1);
  CHECK(im.depth[side] == doctest::Approx(10.0).epsilon(1e-5));
  // Bottom row, y/x = (j + 0.5 - 32)/32, ground at x = 1/dz: the painted band at w in
  // [1, 1.5) shows up right of the centre.
  int lines = 0;
  for (int j = 0; j < 64; ++j) {
    const std::size_t px = 31 * 64 + static_cast<std::size_t>(j);
    const double x = 1.0 / ((31.5 - 16) / 32.0), w = x * (j + 0.5 - 32) / 32.0;
    CHECK(im.tags[px] == ((w >= 1.0 && w < 1.5) ? 6 : 7));
    lines += im.tags[px] == 6;
  }
  CHECK(lines > 0);
}

TEST_CASE("background and bodies do not depend on the thread count") {
  Scene sc = ground_only();
  Box b;
  b.lo = Vec3(8, -2, 0), b.hi = Vec3(9, 2, 3), b.tag = 10, b.rgb = Vec3(10, 20, 200);
  b.texture = 0.3, b.pattern = Pattern::Glass;
  sc.boxes.push_back(b);
  Camera cam = level_camera();
  cam.k = Intrinsics{96, 48, 90.0};
  const Images one = background(sc, cam, 1), four = background(sc, cam, 4);
  CHECK(one.rgb == four.rgb);
  CHECK(one.tags == four.tags);
  CHECK(one.depth == four.depth);

  const std::size_t n = 96 * 48, frames = 5;
  std::vector<Capsule> caps;
  for (std::size_t f = 0; f < frames; ++f)
    caps.push_back(Capsule{Vec3(4, -1.0 + 0.5 * f, 0.2), Vec3(4, -1.0 + 0.5 * f, 1.6), 0.3,
                           Vec3(200, 50, 50)});
  std::vector<std::uint8_t> rgb1(3 * n * frames), tags1(n * frames), vis1(frames);
  std::vector<std::uint8_t> rgb4(rgb1.size()), tags4(tags1.size()), vis4(frames);
  render_bodies(cam, sc.light, one.rgb.data(), one.tags.data(), one.depth.data(), caps.data(),
                1, frames, rgb1.data(), tags1.data(), vis1.data(), 1);
  render_bodies(cam, sc.light, one.rgb.data(), one.tags.data(), one.depth.data(), caps.data(),
                1, frames, rgb4.data(), tags4.data(), vis4.data(), 4);
  CHECK(rgb1 == rgb4);
  CHECK(tags1 == tags4);
  CHECK(vis1 == vis4);
}

TEST_CASE("bodies: tag 4 in front of the background, hidden behind nearer geometry") {
  Scene sc = ground_only();
  Box car;  // a box at x in [3, 3.5] covering the left half of the view
  car.lo = Vec3(3, -10, 0), car.hi = Vec3(3.5, 0, 3), car.tag = 10, car.rgb = Vec3(0, 0, 142);
  sc.boxes.push_back(car);
  const Camera cam = level_camera();
  const Images bg = background(sc, cam, 1);
  // Frame 0: a person at x = 6 behind the car (left, y = -1); frame 1: the same on the
  // right (y = +1), unoccluded; frame 2: wholly behind the camera.
  const std::vector<Capsule> caps = {
      {Vec3(6, -1, 0.3), Vec3(6, -1, 1.5), 0.3, Vec3(200, 0, 0)},
      {Vec3(6, 1, 0.3), Vec3(6, 1, 1.5), 0.3, Vec3(200, 0, 0)},
      {Vec3(-3, 0, 0.3), Vec3(-3, 0, 1.5), 0.3, Vec3(200, 0, 0)}};
  const std::size_t n = 64 * 32;
  std::vector<std::uint8_t> rgb(3 * n * 3), tags(n * 3), vis(3);
  render_bodies(cam, sc.light, bg.rgb.data(), bg.tags.data(), bg.depth.data(), caps.data(), 1,
                3, rgb.data(), tags.data(), vis.data(), 1);
  CHECK(vis[0] == 0);
  CHECK(vis[1] == 1);
  CHECK(vis[2] == 0);
  // Frame 1: the pixel through the capsule axis at row 16 (z = 1 - 0.5/32 * 6 ~ 0.9).
  const int j = static_cast<int>(std::floor(32 + 32.0 * 1 / 6));
  const std::size_t hit = n + 16 * 64 + static_cast<std::size_t>(j);
  CHECK(tags[hit] == 4);
  // Lit from behind (the default sun has +x): ambient 0.45 of (200, 0, 0), a little fog.
  CHECK(rgb[3 * hit] == doctest::Approx(0.45 * 200).epsilon(0.05));
  CHECK(rgb[3 * hit + 1] < 10);
  // Frames keep the background elsewhere.
  for (std::size_t px = 0; px < n; ++px) {
    CHECK(tags[2 * n + px] == bg.tags[px]);
    if (tags[n + px] != 4) CHECK(tags[n + px] == bg.tags[px]);
  }
}

// A street-like scene: ground bands, a parked "car" and a pole in front of a wall, a tree.
Scene cluttered() {
  Scene sc = ground_only();
  Box car, wall;
  car.lo = Vec3(5, -3, 0.3), car.hi = Vec3(5.6, -0.5, 1.4), car.tag = 10;
  wall.lo = Vec3(14, -20, 0), wall.hi = Vec3(15, 20, 6), wall.tag = 1;
  sc.boxes = {car, wall};
  Cylinder pole;
  pole.s = 4, pole.w = 0.8, pole.z0 = 0, pole.z1 = 3, pole.radius = 0.12, pole.tag = 5;
  sc.cylinders = {pole};
  Sphere crown;
  crown.centre = Vec3(7, 2.5, 2.2), crown.radius = 1.0, crown.tag = 9;
  sc.spheres = {crown};
  return sc;
}

TEST_CASE("body_visibility: render_bodies' flags without the images") {
  const Scene sc = cluttered();
  Camera cam = level_camera();
  cam.k = Intrinsics{160, 96, 90.0};
  const Images bg = background(sc, cam, 1);
  // A walker crossing the view at three depths (behind the car, the pole and the crown
  // for some frames), a far one thinner than a pixel, one behind the camera, one at the
  // image edge.
  std::vector<Capsule> caps;
  std::size_t frames = 0;
  for (double x : {6.5, 8.0, 60.0}) {
    for (int k = 0; k <= 24; ++k, ++frames) {
      const double y = -4.0 + k / 3.0, r = x > 50 ? 0.004 : 0.25;
      caps.push_back({Vec3(x, y, 0.3), Vec3(x, y, 1.7), r, Vec3(200, 0, 0)});
      caps.push_back({Vec3(x, y, 1.75), Vec3(x, y, 1.75), r * 0.6, Vec3(200, 0, 0)});
    }
  }
  caps.push_back({Vec3(-3, 0, 0.3), Vec3(-3, 0, 1.5), 0.3, Vec3()});
  caps.push_back({Vec3(-3, 0, 1.6), Vec3(-3, 0, 1.6), 0.2, Vec3()});
  caps.push_back({Vec3(3, -3.4, 0.3), Vec3(3, -3.4, 1.5), 0.3, Vec3()});
  caps.push_back({Vec3(3, -3.4, 1.6), Vec3(3, -3.4, 1.6), 0.2, Vec3()});
  frames += 2;
  const std::size_t n = 160 * 96;
  std::vector<std::uint8_t> rgb(3 * n * frames), tags(n * frames), drawn(frames);
  render_bodies(cam, sc.light, bg.rgb.data(), bg.tags.data(), bg.depth.data(), caps.data(), 2,
                frames, rgb.data(), tags.data(), drawn.data(), 1);
  for (int threads : {1, 3}) {
    std::vector<std::uint8_t> vis(frames, 7);
    body_visibility(sc, cam, caps.data(), 2, frames, vis.data(), threads);
    CHECK(vis == drawn);
  }
  // Both values occur: the comparison could not pass with a constant.
  const auto shown = std::count(drawn.begin(), drawn.end(), 1);
  CHECK(shown > 10);
  CHECK(shown + 5 < static_cast<long>(frames));
  // StreetView::depth is the background pass's depth, bit for bit, at every pixel.
  const StreetView view(sc, cam);
  int differ = 0;
  for (int i = 0; i < 96; ++i)
    for (int j = 0; j < 160; ++j) {
      const float d = view.depth(i, j), want = bg.depth[static_cast<std::size_t>(i) * 160 + j];
      differ += !(d == want || (std::isinf(d) && std::isinf(want)));
    }
  CHECK(differ == 0);
}

TEST_CASE("motion: BVH nodes, rest pose and sampled local transforms") {
  const bsp::testing::TempDir tmp("bsp_test_motion");
  const std::string path = write_bvh(tmp);
  const bsp::Motion mo = bsp::load_motion(path, 20.0);  // resampled at twice the file's rate
  REQUIRE(mo.names.size() >= 2);
  CHECK(mo.names[0] == "Hips");
  CHECK(mo.names[1] == "LeftUpLeg");
  CHECK(mo.parents[0] == -1);
  CHECK(mo.parents[1] == 0);
  CHECK(mo.duration == doctest::Approx(0.3));
  CHECK(mo.frames == 7);  // 0.3 s at 20 fps, both ends
  const std::size_t n = mo.names.size();
  // Rest transform of the child: its OFFSET (row-major 4x4, translation in column 3).
  CHECK(mo.rest[16 * 1 + 3] == doctest::Approx(10.0));
  // Frame 3 (t = 0.15 s) lies halfway between the 30 and 60 degree keys: 45 degrees.
  const double* m = mo.local.data() + 16 * (3 * n + 1);
  CHECK(m[0] == doctest::Approx(std::cos(M_PI / 4)).epsilon(1e-5));
  CHECK(m[4] == doctest::Approx(std::sin(M_PI / 4)).epsilon(1e-5));
  // Root translation keys are interpolated too: z = 2 per file frame.
  CHECK(mo.local[16 * (3 * n) + 11] == doctest::Approx(3.0).epsilon(1e-5));
}

TEST_CASE("motion: errors name the file and the reason") {
  const bsp::testing::TempDir tmp("bsp_test_motion");
  const std::string missing = tmp.path("no_such_motion.bvh");
  try {
    bsp::load_motion(missing);
    FAIL("expected MotionError");
  } catch (const bsp::MotionError& e) {
    CHECK(std::string(e.what()).find(missing) != std::string::npos);
  }
  const std::string path = write_bvh(tmp);
  CHECK_THROWS_AS(bsp::load_motion(path, 0.0), bsp::MotionError);
  CHECK_THROWS_AS(bsp::load_motion(path, 30.0, 3), bsp::MotionError);
}
