// A tiny ray-caster for textured rectangles: renders grey images (and z-depth)
// of a few planes from any camera pose, for exactly known tracking sequences.
#pragma once

#include <vector>

#include <opencv2/core.hpp>

#include "hermes/core/geometry.h"
#include "hermes/core/map_types.h"

namespace hermes::test {

struct TexturedPlane {
  Vec3 origin;         ///< corner of the rectangle in W [m]
  Vec3 e1, e2;         ///< orthonormal in-plane axes (texture x, y)
  double width = 1, height = 1;  ///< extent along e1, e2 [m]
  cv::Mat texture;     ///< 8-bit grey, stretched over the rectangle
};

/// Renders the nearest plane along every pixel ray of a camera at T_W_C; pixels
/// seeing nothing are 0. `depth` (optional) receives z in the camera [m], 0 if none.
cv::Mat renderPlanes(const std::vector<TexturedPlane>& planes, const PinholeIntrinsics& K,
                     const SE3& T_W_C, cv::Mat* depth = nullptr);

/// A room corner: back wall, floor and left wall textured with opencv-doc photos.
/// Empty if the photos are missing.
std::vector<TexturedPlane> roomCornerScene();

}  // namespace hermes::test
