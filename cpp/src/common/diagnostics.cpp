#include "bsp/common/diagnostics.hpp"

#include <Eigen/Core>
#include <assimp/version.h>
#include <libdeflate.h>
#include <opencv2/core/version.hpp>
#include <opencv2/core/utility.hpp>

#include <hdf5.h>

extern "C" {
#include <libavcodec/avcodec.h>
#include <libavformat/avformat.h>
#include <libavutil/avutil.h>
#include <libswscale/swscale.h>
}

namespace bsp {
namespace {
std::string av_ver(unsigned v) {
  return std::to_string(v >> 16) + "." + std::to_string((v >> 8) & 0xff) + "." +
         std::to_string(v & 0xff);
}
}  // namespace

std::map<std::string, std::string> library_versions() {
  std::map<std::string, std::string> v;
  v["bsp_core"] = BSP_VERSION;
  v["ffmpeg"] = av_version_info();
  v["libavcodec"] = av_ver(avcodec_version());
  v["libavformat"] = av_ver(avformat_version());
  v["libavutil"] = av_ver(avutil_version());
  v["libswscale"] = av_ver(swscale_version());
  v["opencv"] = cv::getVersionString();
  unsigned h5_major = 0, h5_minor = 0, h5_release = 0;  // the library's own, as for the others
  H5get_libversion(&h5_major, &h5_minor, &h5_release);
  v["hdf5"] = std::to_string(h5_major) + "." + std::to_string(h5_minor) + "." +
              std::to_string(h5_release);
  v["eigen"] = std::to_string(EIGEN_WORLD_VERSION) + "." + std::to_string(EIGEN_MAJOR_VERSION) +
               "." + std::to_string(EIGEN_MINOR_VERSION);
  v["assimp"] = std::to_string(aiGetVersionMajor()) + "." + std::to_string(aiGetVersionMinor()) +
                "." + std::to_string(aiGetVersionPatch());
  v["libdeflate"] = LIBDEFLATE_VERSION_STRING;
  v["compiler"] = __VERSION__;
  return v;
}

}  // namespace bsp
