#include "bsp/geometry/skeleton.hpp"

namespace bsp::skeleton {

const std::array<const char*, kJoints> kNames = {
    "crl_root",       "crl_hips__C",   "crl_spine__C",    "crl_spine01__C", "crl_shoulder__L",
    "crl_arm__L",     "crl_foreArm__L", "crl_hand__L",    "crl_neck__C",    "crl_Head__C",
    "crl_eye__L",     "crl_eye__R",    "crl_shoulder__R", "crl_arm__R",     "crl_foreArm__R",
    "crl_hand__R",    "crl_thigh__R",  "crl_leg__R",      "crl_foot__R",    "crl_toe__R",
    "crl_toeEnd__R",  "crl_thigh__L",  "crl_leg__L",      "crl_foot__L",    "crl_toe__L",
    "crl_toeEnd__L"};

const std::array<std::int32_t, kJoints> kParents = {-1, 0,  1,  2,  3,  4,  5,  6,  3,
                                                    8,  9,  9,  3,  12, 13, 14, 1,  16,
                                                    17, 18, 19, 1,  21, 22, 23, 24};

const std::array<std::int32_t, kJoints> kFlip = {0,  1,  2,  3,  12, 13, 14, 15, 8,
                                                 9,  11, 10, 4,  5,  6,  7,  21, 22,
                                                 23, 24, 25, 16, 17, 18, 19, 20};

}  // namespace bsp::skeleton
