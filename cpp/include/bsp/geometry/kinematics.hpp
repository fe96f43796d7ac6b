// Rotations, rigid transforms and forward kinematics in the CARLA / Unreal convention
// (docs/dataset-format.md, "5. Geometry conventions"): left-handed, Z up, angles (pitch,
// yaw, roll) in degrees, lengths in metres (or any unit: nothing here depends on it). All
// maths in double precision.
#pragma once
#include <Eigen/Core>
#include <cstddef>
#include <cstdint>
#include <vector>

namespace bsp {

using Mat3 = Eigen::Matrix3d;
using Vec3 = Eigen::Vector3d;

struct Transform {
  Mat3 R = Mat3::Identity();
  Vec3 t = Vec3::Zero();
};

// R = Rz(yaw) * Ry(-pitch) * Rx(-roll) in right-handed elementary matrices.
Mat3 rotation_from_pyr(double pitch_deg, double yaw_deg, double roll_deg);
// Rotation matrices of n transforms [x, y, z, pitch, yaw, roll] stored as float32, `stride`
// floats apart from t (angles at +3..+5), as row-major float32 3x3 matrices at R + 9 i:
// each bitwise equal to static_cast<float>(rotation_from_pyr(...)) of the same angles,
// about 4x faster (vector sin/cos, the scalar path where the float could differ).
// Single-threaded (rotation_f32.cpp).
void rotation_matrices_f32(const float* t, std::size_t stride, std::size_t n, float* R);
// Inverse of rotation_from_pyr: returns (pitch, yaw, roll) in degrees; at gimbal lock
// (|pitch| = 90) roll is set to 0 and yaw absorbs the remaining rotation.
Vec3 pyr_from_rotation(const Mat3& R);

// [x, y, z, pitch, yaw, roll] <-> Transform.
Transform transform_from_array(const double* a6);
void transform_to_array(const Transform& t, double* a6);

inline Transform compose(const Transform& a, const Transform& b) {
  return Transform{a.R * b.R, a.R * b.t + a.t};
}
inline Transform inverse(const Transform& a) {
  Mat3 rt = a.R.transpose();
  return Transform{rt, -(rt * a.t)};
}

// ---- batch kernels over flat, C-contiguous arrays (multi-threaded) -----------------
// Broadcasting: operand X with repeat factor kX is read at index i / kX, so an operand of
// n/kX items serves kX consecutive outputs.
void rotation_matrices(const double* pyr, double* R, std::size_t n);
void rotations_to_euler(const double* R, double* pyr, std::size_t n);
void compose_batch(const double* a, std::size_t ka, const double* b, std::size_t kb,
                   double* out, std::size_t n);
void invert_batch(const double* t, double* out, std::size_t n);
void transform_points_batch(const double* t, std::size_t kt, const double* p,
                            std::size_t kp, double* out, std::size_t n);

// Forward kinematics of `frames` poses of `joints` bones each. parents[j] < j, parents[0]
// = -1. `root` holds one transform per frame (or per `kr` frames; nullptr = identity).
// Output: component-space transforms (frames, joints, 6).
void forward_kinematics(const double* relative, std::size_t frames, std::size_t joints,
                        const std::int32_t* parents, const double* root, std::size_t kr,
                        double* out);
// Throws std::invalid_argument unless parents describe a tree in index order.
void check_parents(const std::int32_t* parents, std::size_t joints);

}  // namespace bsp
