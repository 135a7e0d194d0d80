// KITTI odometry, laid out as KITTI publishes it:
//   <root>/sequences/NN/image_0/000000.png, image_1/…  rectified grey stereo pair
//   <root>/sequences/NN/calib.txt    `P0:` / `P1:` 3x4 projection matrices (row-major)
//   <root>/sequences/NN/times.txt    one stamp [s] per frame (absent: 10 Hz, with a warning)
//   <root>/poses/NN.txt              ground truth, optional: per frame the 3x4 pose of
//                                    the left camera in the first left camera's frame
// The dataset is opened at sequences/NN. The tracked frame (and the ground truth's) is
// the rectified left camera: T_B_C is the identity.
#pragma once

#include <string>
#include <vector>

#include "hermes/core/camera.h"
#include "hermes/core/dataset_frames.h"
#include "hermes/core/status.h"
#include "hermes/core/trajectory.h"

namespace hermes {

/// The rectified stereo camera of calib.txt.
struct KittiCalibration {
  PinholeIntrinsics K;  ///< from P0 (width/height from the first image)
  double baseline = 0;  ///< [m] -P1[0,3] / P1[0,0]
};

/// Reads calib.txt: `P0:` and `P1:` with 12 numbers each; errors name file and line.
Expected<KittiCalibration> readKittiCalibration(const std::string& path);
/// Reads a KITTI poses file (12 numbers per row) with the given stamps; errors name
/// file and line. Fewer rows than stamps is fine (the ground truth covers a prefix).
Expected<Trajectory> readKittiPoses(const std::string& path, const std::vector<double>& stamps);

/// True when `dir` holds image_0/, image_1/ and calib.txt.
bool looksLikeKittiSequence(const std::string& dir);

class KittiDataset {
 public:
  struct Pair {
    double t = 0;
    std::string left_path, right_path;
  };
  static Expected<KittiDataset> open(const std::string& dir);

  const std::string& root() const { return root_; }
  const KittiCalibration& calibration() const { return calib_; }
  const std::vector<Pair>& pairs() const { return pairs_; }
  std::size_t size() const { return pairs_.size(); }
  /// The left camera's poses (empty without poses/NN.txt two levels up).
  const Trajectory& groundTruth() const { return groundtruth_; }
  const std::vector<std::string>& warnings() const { return warnings_; }
  /// Pair i, already rectified; errors name the image path.
  Expected<StereoFrame> load(std::size_t i) const;

 private:
  std::string root_;
  KittiCalibration calib_;
  std::vector<Pair> pairs_;
  Trajectory groundtruth_;
  std::vector<std::string> warnings_;
};

}  // namespace hermes
