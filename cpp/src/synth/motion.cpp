#include "bsp/synth/motion.hpp"

#include <assimp/Importer.hpp>
#include <assimp/anim.h>
#include <assimp/config.h>
#include <assimp/scene.h>

#include <algorithm>
#include <cmath>
#include <map>

#include "bsp/common/errors.hpp"

namespace bsp {
namespace {

[[noreturn]] void fail(const std::string& path, const std::string& why) {
  throw MotionError("cannot load motion '" + path + "': " + why);
}

void put(const aiMatrix4x4& m, double* out) {
  const float* src = m[0];
  for (int k = 0; k < 16; ++k) out[k] = static_cast<double>(src[k]);
}

void flatten(const aiNode* node, int parent, Motion& mo,
             std::vector<const aiNode*>& nodes) {
  const int self = static_cast<int>(nodes.size());
  nodes.push_back(node);
  mo.names.emplace_back(node->mName.C_Str());
  mo.parents.push_back(parent);
  for (unsigned c = 0; c < node->mNumChildren; ++c) flatten(node->mChildren[c], self, mo, nodes);
}

// Key index i with keys[i].mTime <= t < keys[i + 1].mTime (clamped), and the blend factor.
template <class Key>
std::size_t find_key(const Key* keys, unsigned n, double t, double& alpha) {
  if (n <= 1 || t <= keys[0].mTime) return alpha = 0.0, 0;
  if (t >= keys[n - 1].mTime) return alpha = 0.0, n - 1;
  const Key* it = std::upper_bound(keys, keys + n, t,
                                   [](double v, const Key& k) { return v < k.mTime; });
  const std::size_t i = static_cast<std::size_t>(it - keys) - 1;
  const double span = keys[i + 1].mTime - keys[i].mTime;
  alpha = span > 0 ? (t - keys[i].mTime) / span : 0.0;
  return i;
}

aiVector3D lerp_keys(const aiVectorKey* keys, unsigned n, double t, const aiVector3D& dflt) {
  if (n == 0) return dflt;
  double a;
  const std::size_t i = find_key(keys, n, t, a);
  if (a == 0.0) return keys[i].mValue;
  const auto f = static_cast<ai_real>(a);
  return keys[i].mValue + (keys[i + 1].mValue - keys[i].mValue) * f;
}

aiQuaternion slerp_keys(const aiQuatKey* keys, unsigned n, double t, const aiQuaternion& dflt) {
  if (n == 0) return dflt;
  double a;
  const std::size_t i = find_key(keys, n, t, a);
  if (a == 0.0) return keys[i].mValue;
  aiQuaternion out;
  aiQuaternion::Interpolate(out, keys[i].mValue, keys[i + 1].mValue, static_cast<ai_real>(a));
  return out.Normalize();
}

aiMatrix4x4 sample_channel(const aiNodeAnim* ch, const aiNode* node, double ticks) {
  aiVector3D scale, pos;
  aiQuaternion rot;
  node->mTransformation.Decompose(scale, rot, pos);
  pos = lerp_keys(ch->mPositionKeys, ch->mNumPositionKeys, ticks, pos);
  rot = slerp_keys(ch->mRotationKeys, ch->mNumRotationKeys, ticks, rot);
  scale = lerp_keys(ch->mScalingKeys, ch->mNumScalingKeys, ticks, scale);
  return aiMatrix4x4(scale, rot, pos);
}

const aiScene* import(Assimp::Importer& imp, const std::string& path) {
  // Keep the file's own node tree: no pivot helper nodes, no post-processing.
  imp.SetPropertyBool(AI_CONFIG_IMPORT_FBX_PRESERVE_PIVOTS, false);
  const aiScene* sc = imp.ReadFile(path, 0);
  if (!sc) fail(path, imp.GetErrorString());
  if (!sc->mRootNode) fail(path, "the file has no node hierarchy");
  if (sc->mNumAnimations == 0) fail(path, "the file holds no animation");
  return sc;
}

}  // namespace

Motion load_motion(const std::string& path, double fps, int index) {
  if (!(fps > 0 && fps <= 1000)) fail(path, "sampling rate must be in (0, 1000] fps");
  Assimp::Importer imp;
  const aiScene* sc = import(imp, path);
  if (index < 0 || static_cast<unsigned>(index) >= sc->mNumAnimations)
    fail(path, "animation index " + std::to_string(index) + " out of range (the file has " +
                   std::to_string(sc->mNumAnimations) + ")");
  const aiAnimation* anim = sc->mAnimations[index];
  Motion mo;
  mo.path = path;
  mo.fps = fps;
  mo.animation = anim->mName.C_Str();
  std::vector<const aiNode*> nodes;
  flatten(sc->mRootNode, -1, mo, nodes);
  const double tps = anim->mTicksPerSecond > 0 ? anim->mTicksPerSecond : 25.0;  // assimp's
  mo.duration = std::max(0.0, anim->mDuration / tps);
  // Frame times are often rounded in the file (BVH "Frame Time: 0.033333"): tolerate it.
  mo.frames = static_cast<std::size_t>(std::floor(mo.duration * fps + 0.01)) + 1;
  std::map<std::string, const aiNodeAnim*> channels;
  for (unsigned c = 0; c < anim->mNumChannels; ++c)
    channels[anim->mChannels[c]->mNodeName.C_Str()] = anim->mChannels[c];
  const std::size_t n = nodes.size();
  mo.rest.resize(n * 16);
  mo.local.resize(mo.frames * n * 16);
  for (std::size_t j = 0; j < n; ++j) {
    put(nodes[j]->mTransformation, mo.rest.data() + 16 * j);
    const auto it = channels.find(mo.names[j]);
    for (std::size_t f = 0; f < mo.frames; ++f) {
      double* out = mo.local.data() + 16 * (f * n + j);
      if (it == channels.end()) {
        put(nodes[j]->mTransformation, out);
      } else {
        put(sample_channel(it->second, nodes[j], static_cast<double>(f) / fps * tps), out);
      }
    }
  }
  return mo;
}

}  // namespace bsp
