// The 26-joint CARLA pedestrian skeleton (docs/dataset-format.md, "4. The 26-joint skeleton").
#pragma once
#include <array>
#include <cstdint>

namespace bsp::skeleton {

constexpr int kJoints = 26;
constexpr int kRoot = 0, kHips = 1, kNeck = 8;

extern const std::array<const char*, kJoints> kNames;
extern const std::array<std::int32_t, kJoints> kParents;
// Output joint i of a horizontally flipped pose takes input joint kFlip[i].
extern const std::array<std::int32_t, kJoints> kFlip;

}  // namespace bsp::skeleton
