// Skeletal animation import (BVH, FBX, glTF and whatever else assimp reads) for bsp-synth's
// --motion option. The file's node tree is flattened depth-first and its first animation is
// resampled at a fixed rate into per-node LOCAL transforms; retargeting onto the CARLA
// skeleton happens in Python (bsp_fast/synth/motion.py), which only needs these.
#pragma once
#include <cstddef>
#include <string>
#include <vector>

namespace bsp {

struct Motion {
  std::string path;
  std::vector<std::string> names;  // node names, depth-first (parents before children)
  std::vector<int> parents;        // -1 for the root node
  std::vector<double> rest;        // (nodes, 4, 4) row-major local transforms of the file
  std::vector<double> local;       // (frames, nodes, 4, 4) row-major sampled local transforms
  std::size_t frames = 0;
  double fps = 30.0;               // sampling rate of `local`
  double duration = 0.0;           // seconds of the source animation
  std::string animation;           // name of the animation that was sampled
};

// Loads `path` and samples animation `index` at `fps` (positions and scales linearly
// interpolated, rotations slerped; nodes without a channel keep their rest transform).
// Throws MotionError naming the file and assimp's reason, or why the file is unusable
// (no animation, no node tree, bad index or rate).
Motion load_motion(const std::string& path, double fps = 30.0, int index = 0);

}  // namespace bsp
