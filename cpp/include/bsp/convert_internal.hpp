// Pieces of convert_csv shared between its source files (not a public header).
#pragma once
#include <vector>

#include "bsp/clips.hpp"
#include "bsp/convert.hpp"
#include "bsp/csv.hpp"
#include "bsp/h5.hpp"

namespace bsp::detail {

void write_split(const h5::Group& g, const PoseTable& t, const Plan& plan,
                 const std::vector<Clip>& clips, int L, const ConvertOptions& opt,
                 ConvertProgress* progress);
void write_clip_meta(const h5::Group& g, const PoseTable& t, const Plan& plan,
                     const std::vector<Clip>& clips, int L);
// Per recording: largest disagreement between the pose columns (mm) and between
// pose.camera and the projection of pose.world (px).
std::vector<VerifyRow> verify_recordings(const PoseTable& t, const Plan& plan, double fov,
                                         int threads);

}  // namespace bsp::detail
