// RGB-D folder layouts:
//  * TUM RGB-D: rgb.txt, depth.txt (`timestamp filename`, '#' comments), optional
//    groundtruth.txt (TUM trajectory), optional camera.yaml.
//  * ICL-NUIM's "TUM RGB-D compatible" release: associations.txt with rows
//    `K depth/K.png K rgb/K.png` (the stamps are frame indices at 30 Hz; TUM's own
//    `t_rgb rgb t_depth depth` order is read too), ground truth `*.gt.freiburg` in the
//    folder or the one above it, optional camera.yaml (default: ICL-NUIM's camera).
//
// camera.yaml (Hermes' small format, written by our renderer):
//   camera_model: pinhole   # optional; only pinhole
//   fx: 481.2               # [px]
//   fy: 480.0
//   cx: 319.5
//   cy: 239.5
//   k1: 0.262383            # optional colour lens distortion, plumb_bob order
//   k2: -0.953104           #   k1 k2 p1 p2 k3 (absent = 0 = undistorted images)
//   p1: -0.005358
//   p2: 0.002628
//   k3: 1.163314
//   width: 640              # [px]
//   height: 480
//   depth_scale: 5000       # depth PNG value per metre
//   rate_hz: 30             # optional
//   T_B_C: [16 numbers]     # optional, row-major 4x4 body <- camera (default identity)
// A Hermes RGB-D camera file (key `kind: rgbd`, config/cameras/tum_fr1.yaml
// etc.) is accepted as camera.yaml too.
#pragma once

#include <string>
#include <vector>

#include "hermes/core/camera.h"
#include "hermes/core/dataset_frames.h"
#include "hermes/core/status.h"
#include "hermes/core/trajectory.h"

namespace hermes {

/// Reads camera.yaml (format above, distortion into RgbdCamera::dist); errors
/// name the file and key.
Expected<RgbdCamera> readTumCameraYaml(const std::string& path);
/// Writes camera.yaml (format above) with full precision.
Status writeTumCameraYaml(const std::string& path, const RgbdCamera& cam);

/// ICL-NUIM's camera (fx 481.20, fy 480.00, cx 319.5, cy 239.5, 640x480,
/// depth scale 5000), used when a folder has no camera.yaml.
RgbdCamera iclNuimDefaultCamera();

/// ICL-NUIM ground truth (`*.gt.freiburg`) as published: TUM rows whose stamps are
/// frame indices (all integers: converted to index / rate_hz seconds) in the fy < 0
/// convention of ICL-NUIM's renderer. Returned in the convention of the images as
/// stored (fy > 0): T <- M T M with M = diag(1, -1, 1), a mirror of the camera's and
/// the world's y axis that keeps every distance (so the ATE against it is the true one).
Expected<Trajectory> readIclNuimGroundTruth(const std::string& path, double rate_hz = 30.0);
/// True when the file name ends in `.gt.freiburg` (ICL-NUIM's ground-truth name).
bool isIclNuimGroundTruthName(const std::string& path);

/// One line of rgb.txt / depth.txt.
struct TumImageRow {
  double t = 0;          ///< [s]
  std::string filename;  ///< relative to the dataset folder
};
/// Reads `timestamp filename` lines; errors name path and line.
Expected<std::vector<TumImageRow>> readTumImageList(const std::string& path);

struct TumOptions {
  double max_dt = 0.02;      ///< [s] rgb-depth association tolerance
  double depth_scale = 0.0;  ///< > 0 overrides camera.yaml / the default 5000
};

/// A TUM RGB-D / ICL-NUIM sequence with associated rgb/depth pairs.
class TumDataset {
 public:
  struct Pair {
    double t_rgb = 0, t_depth = 0;
    std::string rgb_path, depth_path;
  };
  struct SkipCounts {
    int rgb_missing_image = 0;    ///< list rows whose file does not exist
    int depth_missing_image = 0;
    int rgb_unmatched = 0;        ///< no depth within max_dt
    int depth_unmatched = 0;
  };

  static Expected<TumDataset> open(const std::string& dir, const TumOptions& opt = {});

  const std::string& root() const { return root_; }
  /// The camera, with the colour lens distortion (RgbdCamera::dist) that
  /// keypoints of load()ed images still carry.
  const RgbdCamera& camera() const { return camera_; }
  /// True for ICL-NUIM's published layout (associations.txt, *.gt.freiburg).
  bool iclNuimLayout() const { return icl_layout_; }
  /// True when camera.yaml was absent and ICL-NUIM defaults are used.
  bool defaultCamera() const { return default_camera_; }
  /// Human-readable notes (e.g. the default-intrinsics fallback).
  const std::vector<std::string>& warnings() const { return warnings_; }
  const std::vector<Pair>& pairs() const { return pairs_; }
  std::size_t size() const { return pairs_.size(); }
  const SkipCounts& skipped() const { return skipped_; }
  bool hasGroundTruth() const { return !groundtruth_.empty(); }
  /// groundtruth.txt as read, or ICL-NUIM's *.gt.freiburg as readIclNuimGroundTruth()
  /// gives it (pose of the body in the world; with the default identity T_B_C this is
  /// the camera pose, as in TUM).
  const Trajectory& groundTruth() const { return groundtruth_; }

  /// Loads pair i: colour, grey and metric depth. Errors name the image path.
  Expected<RgbdFrame> load(std::size_t i) const;

 private:
  /// The rest of open() for ICL-NUIM's layout (camera already read).
  static Expected<TumDataset> openIclNuim(TumDataset ds);
  std::string root_;
  RgbdCamera camera_;
  bool default_camera_ = false;
  bool icl_layout_ = false;
  std::vector<std::string> warnings_;
  std::vector<Pair> pairs_;
  SkipCounts skipped_;
  Trajectory groundtruth_;
};

/// One-to-one association of two sorted stamp lists: pairs with |dt| <= max_dt,
/// closest first (as TUM's associate.py). Returns index pairs sorted by a.
std::vector<std::pair<std::size_t, std::size_t>> associateStamps(const std::vector<double>& a,
                                                                 const std::vector<double>& b,
                                                                 double max_dt);

}  // namespace hermes
