// bsp-synth's animation import (bsp/synth/motion.hpp): a tiny BVH written here, read via assimp.
#include <doctest/doctest.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <string>

#include "bsp/common/errors.hpp"
#include "bsp/synth/motion.hpp"

namespace {
std::string temp_path(const char* name) {
  return std::string(std::getenv("TMPDIR") ? std::getenv("TMPDIR") : "/tmp") + "/" + name;
}

// Root + one child; the child turns about Z by 0, 30, 60, 90 degrees over 4 frames at 10 fps.
std::string write_bvh() {
  const std::string path = temp_path("bsp_test_motion.bvh");
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

TEST_CASE("motion: BVH nodes, rest pose and sampled local transforms") {
  const std::string path = write_bvh();
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
  std::remove(path.c_str());
}

TEST_CASE("motion: errors name the file and the reason") {
  const std::string missing = temp_path("bsp_no_such_motion.bvh");
  try {
    bsp::load_motion(missing);
    FAIL("expected MotionError");
  } catch (const bsp::MotionError& e) {
    CHECK(std::string(e.what()).find(missing) != std::string::npos);
  }
  const std::string path = write_bvh();
  CHECK_THROWS_AS(bsp::load_motion(path, 0.0), bsp::MotionError);
  CHECK_THROWS_AS(bsp::load_motion(path, 30.0, 3), bsp::MotionError);
  std::remove(path.c_str());
}
