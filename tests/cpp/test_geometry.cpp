#include <doctest/doctest.h>

#include <cmath>
#include <fstream>
#include <map>
#include <random>
#include <sstream>
#include <string>

#include <Eigen/Dense>

#include "bsp/common/parallel.hpp"
#include "bsp/geometry/camera.hpp"
#include "bsp/geometry/kinematics.hpp"
#include "bsp/geometry/skeleton.hpp"

using namespace bsp;

namespace {
// Reads the reference skeleton YAML (fixed layout: joint, location x/y/z, rotation
// pitch/yaw/roll) into (26, 6) in file units, in skeleton joint order.
std::vector<double> read_skeleton(const std::string& file) {
  std::ifstream in(std::string(BSP_SKELETON_DIR) + "/" + file);
  REQUIRE(in.good());
  std::map<std::string, std::map<std::string, double>> joints;
  std::string line, joint;
  while (std::getline(in, line)) {
    const auto colon = line.find(':');
    if (colon == std::string::npos) continue;
    std::string key = line.substr(0, colon);
    const std::size_t indent = key.find_first_not_of(' ');
    key = key.substr(indent);
    const std::string value = line.substr(colon + 1);
    if (indent == 2) joint = key;
    else if (indent == 6 && !joint.empty()) joints[joint][key] = std::stod(value);
  }
  std::vector<double> out;
  for (const char* name : skeleton::kNames) {
    auto& j = joints.at(name);
    for (const char* k : {"x", "y", "z", "pitch", "yaw", "roll"}) out.push_back(j.at(k));
  }
  return out;
}
}  // namespace

TEST_CASE("rotation matrix follows the CARLA convention") {
  // yaw 90: x axis -> y axis (left-handed Z up: turning right).
  Mat3 R = rotation_from_pyr(0, 90, 0);
  CHECK((R * Vec3(1, 0, 0) - Vec3(0, 1, 0)).norm() < 1e-12);
  // pitch 90: x axis -> z axis (nose up).
  R = rotation_from_pyr(90, 0, 0);
  CHECK((R * Vec3(1, 0, 0) - Vec3(0, 0, 1)).norm() < 1e-12);
  // roll 90: y axis -> -z? R[:,1] = (cy sp sr - sy cr, sy sp sr + cy cr, -cp sr) = (0,0,-1)
  R = rotation_from_pyr(0, 0, 90);
  CHECK((R * Vec3(0, 1, 0) - Vec3(0, 0, -1)).norm() < 1e-12);
  CHECK(std::abs(R.determinant() - 1.0) < 1e-12);
}

TEST_CASE("euler round trip away from gimbal lock") {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> pitch(-89, 89), ang(-179.9, 179.9);
  for (int i = 0; i < 2000; ++i) {
    const Vec3 e(pitch(rng), ang(rng), ang(rng));
    const Vec3 back = pyr_from_rotation(rotation_from_pyr(e.x(), e.y(), e.z()));
    CHECK((back - e).cwiseAbs().maxCoeff() < 1e-6);
  }
  // At gimbal lock the matrix (not the angles) must round-trip.
  const Mat3 R = rotation_from_pyr(90, 30, 20);
  const Vec3 e = pyr_from_rotation(R);
  CHECK((rotation_from_pyr(e.x(), e.y(), e.z()) - R).cwiseAbs().maxCoeff() < 1e-9);
}

TEST_CASE("compose and inverse") {
  const double a6[6] = {1, 2, 3, 10, 20, 30}, b6[6] = {-4, 5, 0.5, -40, 170, 5};
  const Transform a = transform_from_array(a6), b = transform_from_array(b6);
  const Transform id = compose(a, inverse(a));
  CHECK((id.R - Mat3::Identity()).norm() < 1e-12);
  CHECK(id.t.norm() < 1e-12);
  const Vec3 p(0.3, -2, 7);
  const Transform ab = compose(a, b);
  CHECK(((ab.R * p + ab.t) - (a.R * (b.R * p + b.t) + a.t)).norm() < 1e-12);
}

TEST_CASE("forward kinematics of sk_female reproduces sk_female_absolute") {
  const auto rel = read_skeleton("sk_female_relative.yaml");
  const auto abs = read_skeleton("sk_female_absolute.yaml");
  std::vector<double> out(rel.size());
  forward_kinematics(rel.data(), 1, skeleton::kJoints, skeleton::kParents.data(), nullptr, 1,
                     out.data());
  for (int j = 0; j < skeleton::kJoints; ++j) {
    CAPTURE(skeleton::kNames[j]);
    for (int k = 0; k < 3; ++k) CHECK(std::abs(out[6 * j + k] - abs[6 * j + k]) < 1e-4);
    const Mat3 Ro = rotation_from_pyr(out[6 * j + 3], out[6 * j + 4], out[6 * j + 5]);
    const Mat3 Ra = rotation_from_pyr(abs[6 * j + 3], abs[6 * j + 4], abs[6 * j + 5]);
    CHECK((Ro - Ra).cwiseAbs().maxCoeff() < 1e-4);
  }
}

TEST_CASE("batch FK is identical for any thread count") {
  const auto rel = read_skeleton("sk_male_relative.yaml");
  const std::size_t frames = 20000;
  std::vector<double> many(frames * rel.size());
  std::mt19937 rng(3);
  std::normal_distribution<double> n(0, 20);
  for (std::size_t f = 0; f < frames; ++f)
    for (std::size_t i = 0; i < rel.size(); ++i)
      many[f * rel.size() + i] = rel[i] + ((i % 6) >= 3 ? n(rng) : 0.0);
  std::vector<double> one(many.size()), two(many.size());
  set_num_threads(1);
  forward_kinematics(many.data(), frames, 26, skeleton::kParents.data(), nullptr, 1, one.data());
  set_num_threads(2);
  forward_kinematics(many.data(), frames, 26, skeleton::kParents.data(), nullptr, 1, two.data());
  set_num_threads(0);
  CHECK(one == two);
}

TEST_CASE("projection by hand") {
  const Intrinsics k{1600, 600, 90};
  CHECK(k.focal() == doctest::Approx(800));
  const double cam6[6] = {10, 20, 2, 0, 90, 0};  // looking along +y
  const Transform cam = transform_from_array(cam6);
  double uv[2];
  project_point(cam, k, Vec3(10, 30, 2), uv);  // on the optical axis, 10 m ahead
  CHECK(uv[0] == doctest::Approx(800));
  CHECK(uv[1] == doctest::Approx(300));
  project_point(cam, k, Vec3(9, 30, 2), uv);  // camera's right is world -x here
  CHECK(uv[0] == doctest::Approx(880));       // 1 m right at 10 m: f/10 = 80 px
  project_point(cam, k, Vec3(10, 30, 3), uv);  // 1 m up
  CHECK(uv[1] == doctest::Approx(220));
  project_point(cam, k, Vec3(10, 10, 2), uv);  // behind
  CHECK(std::isnan(uv[0]));
  CHECK(std::isnan(uv[1]));
}

TEST_CASE("in_frame is the recorder's loose rule") {
  const double inside[4] = {10, 10, 20, 20};
  const double straddle[4] = {-5, 700, 1700, -3};  // any u>=0, any v>=0, any u<=W, any v<=H
  const double left[4] = {-5, 10, -1, 20};
  const double nan_joint[4] = {10, 10, NAN, NAN};
  std::uint8_t out = 0;
  in_frame_batch(inside, 1, 2, 1600, 600, &out);
  CHECK(out == 1);
  in_frame_batch(straddle, 1, 2, 1600, 600, &out);
  CHECK(out == 1);
  in_frame_batch(left, 1, 2, 1600, 600, &out);
  CHECK(out == 0);
  in_frame_batch(nan_joint, 1, 2, 1600, 600, &out);
  CHECK(out == 0);
}

TEST_CASE("parents must form a tree in index order") {
  const std::int32_t bad[3] = {-1, 2, 0};
  CHECK_THROWS_AS(check_parents(bad, 3), std::invalid_argument);
  CHECK_NOTHROW(check_parents(skeleton::kParents.data(), 26));
}
