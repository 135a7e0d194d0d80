// Ray casting of a render::Scene through a camera: per-pixel rays are
// precomputed once in the camera frame (through the lens distortion, so the
// output is the real distorted image); per frame they are only rotated.
#pragma once

#include <cstdint>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include "hermes/core/camera.h"
#include "hermes/core/geometry.h"
#include "hermes/core/render/scene.h"

namespace hermes {
namespace render {

/// Per-pixel camera-frame rays with z = 1 (so the hit distance along a ray is
/// the z-depth) and the angular size of each pixel, plus tile cones for culling.
class RayGrid {
 public:
  /// Rays of a distorted pinhole-radtan camera (pixel centres).
  static RayGrid fromRadtan(const PinholeRadtan& cam);
  /// Rays of an undistorted pinhole camera.
  static RayGrid fromPinhole(const PinholeIntrinsics& K);

  int width() const { return w_; }
  int height() const { return h_; }
  /// Camera-frame ray (x, y, 1) of pixel (u, v).
  const Eigen::Vector3f& ray(int u, int v) const { return ray_[static_cast<std::size_t>(v) * w_ + u]; }
  /// Inverse of d(x, y)/d(u, v) at pixel (u, v), row-major (a, b; c, d): turns a
  /// small normalised image motion into pixels through the lens distortion.
  const Eigen::Vector4f& pixelsPerNormalised(int u, int v) const {
    return jinv_[static_cast<std::size_t>(v) * w_ + u];
  }

  static constexpr int kTile = 16;
  struct Tile {
    Eigen::Vector3f axis;  ///< unit centre direction (camera frame)
    float cos_half = 1;    ///< cosine of the cone half angle covering the tile
    float half = 0;        ///< half angle [rad]
  };

 private:
  friend class Raycaster;
  void finish();
  int w_ = 0, h_ = 0;
  std::vector<Eigen::Vector3f> ray_;   ///< (x, y, 1) per pixel, row-major
  std::vector<float> pix_angle_;       ///< [rad] per pixel
  std::vector<Eigen::Vector4f> jinv_;  ///< see pixelsPerNormalised
  std::vector<Tile> tiles_;
  int tiles_x_ = 0, tiles_y_ = 0;
};

/// Output of one render: radiance (CV_32F, grey levels 0..255 before the
/// sensor), z-depth (CV_32F, metres) and the hit face (CV_32S, box*6+face,
/// box 0 = room, -1 = no hit).
struct RenderOutput {
  cv::Mat radiance, depth, face;
  cv::Mat scratch;  ///< internal edge mask, reused between renders
};

class Raycaster {
 public:
  Raycaster(const Scene& scene, RayGrid rays);
  /// Renders the scene seen by a camera at T_W_C. Depth is filled when want_depth;
  /// the face map is always filled (want_face kept for clarity).
  void render(const SE3& T_W_C, RenderOutput* out, bool want_depth = false,
              bool want_face = false) const;
  const RayGrid& rays() const { return rays_; }
  /// Puts the scene's moving objects where they are at time t [s] (no-op
  /// without movers); renders until the next call see them there.
  void placeMovers(double t);

 private:
  struct Hit;
  void castRay(const Eigen::Vector3f& o, const Eigen::Vector3f& d, float range_scale,
               const int* cand, int ncand, Hit* hit) const;
  float shade(const Eigen::Vector3f& o, const Eigen::Vector3f& d, const Hit& hit,
              float pix_angle, float ray_norm) const;

  const Scene& scene_;
  RayGrid rays_;
  struct Level {
    const std::uint8_t* data;
    int w, h;
    std::size_t step;
  };
  std::vector<std::vector<Level>> levels_;  ///< raw view of every texture's mip levels
  std::vector<Eigen::Vector3f> lo_, hi_;  ///< object bounds in float
  Eigen::Vector3f room_lo_, room_hi_;
  float inv_texel_ = 1;
  std::vector<Eigen::Vector3f> centre_;  ///< bounding sphere per object
  std::vector<float> radius_;
};

}  // namespace render
}  // namespace hermes
