// Textures of the synthetic renderer: mip-mapped 8-bit grey images laid on
// planar faces, and the procedural / photographic synthesis of their content.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

namespace hermes {
namespace render {

/// A grey texture with its mip pyramid (level 0 = full resolution, each next
/// level half the size, low-pass filtered with cv::pyrDown).
struct MipTexture {
  std::vector<cv::Mat> levels;  ///< CV_8UC1, continuous
  /// Builds the pyramid down to a few texels.
  static MipTexture fromImage(const cv::Mat& grey8);
};

/// Photographs used as texture material (grey, 8-bit). Empty when the folder
/// holding them is missing; synthesis then falls back to procedural content.
struct PhotoLibrary {
  std::vector<cv::Mat> photos;
  std::vector<std::string> names;
  std::string folder;
  /// Loads every readable image of `folder` whose name is in the built-in list
  /// (natural photos of Debian's opencv-doc examples). Missing files are skipped.
  static PhotoLibrary load(const std::string& folder = defaultFolder());
  static std::string defaultFolder();
};

/// What a face texture is made of (recorded in scene.json).
enum class TextureStyle : std::uint8_t {
  kRich = 0,   ///< panels of photos, bricks, tiles, blobs, text marks over noise
  kPoor = 1,   ///< near-uniform with faint large-scale gradients only
};

/// Synthesises a face texture of w x h texels (texel_m metres per texel),
/// deterministic for `seed`. `poor_fraction` is the share of panels (rich
/// style) left near-uniform.
cv::Mat synthesizeTexture(int w, int h, double texel_m, TextureStyle style, double poor_fraction,
                          std::uint64_t seed, const PhotoLibrary& photos);

}  // namespace render
}  // namespace hermes
