#include <doctest/doctest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
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
#include "geometry/trig_simd.hpp"  // white-box: the bound rotation_matrices_f32 relies on

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

TEST_CASE("vector sin/cos lie within 2^-44 (relative) of libm's: rotation_matrices_f32's bound") {
  std::mt19937_64 rng(7);
  for (double range : {2.0, 360.0, 1e4, 1e6}) {
    std::uniform_real_distribution<double> u(-range, range);
    std::vector<double> deg(40001), s(deg.size()), c(deg.size());  // odd: scalar tail too
    for (std::size_t i = 0; i < deg.size(); ++i) {
      const float a = static_cast<float>(u(rng));
      const float k90 = static_cast<float>(90.0 * std::round(a / 90.0));  // sin or cos ~ 0
      deg[i] = i % 4 == 0 ? k90 : i % 4 == 1 ? std::nextafter(k90, 2e6f) : a;
    }
    simd::sin_cos_deg_vector(deg.data(), s.data(), c.data(), deg.size());
    double worst = 0;
    std::size_t zeros = 0;  // libm's sin or cos exactly 0 for a non-zero angle: none
    for (std::size_t i = 0; i < deg.size(); ++i) {
      if (deg[i] == 0) continue;  // rotation_matrices_f32 sets sin(+-0) and cos(+-0) itself
      const double a = deg[i] * (M_PI / 180.0), S = std::sin(a), C = std::cos(a);
      zeros += S == 0 || C == 0;
      worst = std::max({worst, std::fabs(s[i] - S) / std::fabs(S), std::fabs(c[i] - C) / std::fabs(C)});
    }
    CHECK(zeros == 0);
    CHECK(worst <= 0x1p-44);
  }
}

TEST_CASE("rotation_matrices_f32 equals the scalar rotation_from_pyr cast to float, bit for bit") {
  std::mt19937_64 rng(11);
  std::vector<float> t;  // (n, 6): location then angles
  auto add = [&](float p, float y, float r) { t.insert(t.end(), {1.f, 2.f, 3.f, p, y, r}); };
  const float inf = INFINITY, nan = NAN;
  for (float a : {0.f, -0.f, 90.f, -90.f, 180.f, -180.f, 360.f, 45.f, 1e-30f, 1e6f, 1.5e6f,
                  1e30f, inf, -inf, nan}) {
    add(a, 0.f, 0.f), add(0.f, a, 0.f), add(0.f, 0.f, a), add(a, a, a), add(a, 33.f, -71.f);
  }
  for (double range : {1.0, 180.0, 360.0, 1e4, 1e6}) {
    std::uniform_real_distribution<double> u(-range, range);
    for (int i = 0; i < 60000; ++i)
      add(static_cast<float>(u(rng)), static_cast<float>(u(rng)), static_cast<float>(u(rng)));
  }
  const std::size_t n = t.size() / 6;
  std::vector<float> got(9 * n), want(9 * n);
  rotation_matrices_f32(t.data(), 6, n, got.data());
  for (std::size_t i = 0; i < n; ++i) {
    const Mat3 R = rotation_from_pyr(t[6 * i + 3], t[6 * i + 4], t[6 * i + 5]);
    for (int k = 0; k < 9; ++k) want[9 * i + static_cast<std::size_t>(k)] = static_cast<float>(R(k / 3, k % 3));
  }
  std::size_t differ = 0;
  for (std::size_t k = 0; k < got.size(); ++k)
    differ += std::memcmp(&got[k], &want[k], sizeof(float)) != 0;
  CHECK(differ == 0);
  // A stride other than 6, and n not a multiple of the vector chunk.
  const std::vector<float> pyr = {0.f, 0.f, 0.f,  // angles at +3 of each stride-3 item
                                  10.f, 20.f, 30.f, -5.f, 175.f, 89.f, 0.5f, -0.25f, 1000.f};
  std::vector<float> m(27);
  rotation_matrices_f32(pyr.data(), 3, 3, m.data());
  for (std::size_t i = 0; i < 3; ++i) {
    const Mat3 R = rotation_from_pyr(pyr[3 * i + 3], pyr[3 * i + 4], pyr[3 * i + 5]);
    for (int k = 0; k < 9; ++k) CHECK(m[9 * i + static_cast<std::size_t>(k)] == static_cast<float>(R(k / 3, k % 3)));
  }
}
