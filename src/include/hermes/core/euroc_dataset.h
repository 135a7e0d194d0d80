// EuRoC ASL folder layout: mav0/cam{0,1}/{data.csv,data/*.png,sensor.yaml},
// mav0/state_groundtruth_estimate0/data.csv.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "hermes/core/camera.h"
#include "hermes/core/dataset_frames.h"
#include "hermes/core/status.h"
#include "hermes/core/trajectory.h"

namespace hermes {

/// Reads a EuRoC camera `sensor.yaml` (the "%YAML:1.0" directive line is
/// tolerated). Only camera_model pinhole + distortion_model radial-tangential
/// are supported; anything else is an error naming the file.
Expected<PinholeRadtan> readEurocCameraYaml(const std::string& path);

/// Writes `cam` in the same sensor.yaml format (readable by EuRoC tools and
/// by readEurocCameraYaml). `comment` goes into the file's comment field.
Status writeEurocCameraYaml(const std::string& path, const PinholeRadtan& cam,
                            const std::string& comment = "Hermes camera");

/// One row of a camera data.csv.
struct EurocImageRow {
  std::int64_t stamp_ns = 0;
  std::string filename;  ///< relative to the camera's data/ folder
};

/// Reads `#timestamp [ns],filename` rows; errors name path and line.
/// Stamps must strictly increase.
Expected<std::vector<EurocImageRow>> readEurocImageCsv(const std::string& path);

/// Ground truth `state_groundtruth_estimate0/data.csv` (ns, p xyz, q wxyz, ...)
/// as the body pose in the world, t in seconds. `stamps_ns` (optional) gets the
/// exact integer stamps. Errors name path and line.
Expected<Trajectory> readEurocGroundTruth(const std::string& path,
                                          std::vector<std::int64_t>* stamps_ns = nullptr);

/// A EuRoC sequence with matched stereo pairs; images load lazily.
class EurocDataset {
 public:
  struct Pair {
    std::int64_t stamp_ns = 0;
    std::string left_path, right_path;  ///< absolute/joined paths of the PNGs
  };
  /// What the reader dropped, so that users can see it.
  struct SkipCounts {
    int cam0_missing_image = 0;  ///< csv rows whose PNG does not exist
    int cam1_missing_image = 0;
    int cam0_unpaired = 0;       ///< rows with an image but no partner stamp
    int cam1_unpaired = 0;
  };

  /// `dir` may be the sequence folder (holding mav0/) or mav0 itself.
  static Expected<EurocDataset> open(const std::string& dir);

  const std::string& mav0() const { return mav0_; }
  const PinholeRadtan& cam0() const { return cam0_; }
  const PinholeRadtan& cam1() const { return cam1_; }
  const std::vector<Pair>& pairs() const { return pairs_; }
  std::size_t size() const { return pairs_.size(); }
  const SkipCounts& skipped() const { return skipped_; }
  bool hasGroundTruth() const { return !groundtruth_.empty(); }
  /// Body (IMU) pose in the world, t [s].
  const Trajectory& groundTruth() const { return groundtruth_; }
  const std::vector<std::int64_t>& groundTruthStampsNs() const { return gt_stamps_ns_; }

  /// Loads pair i (grey, unrectified). Errors name the image path.
  Expected<StereoFrame> load(std::size_t i) const;

 private:
  std::string mav0_;
  PinholeRadtan cam0_, cam1_;
  std::vector<Pair> pairs_;
  SkipCounts skipped_;
  Trajectory groundtruth_;
  std::vector<std::int64_t> gt_stamps_ns_;
};

/// Loads a grey image and checks its size; errors name the path.
Expected<cv::Mat> loadGrayImage(const std::string& path, int width, int height);

}  // namespace hermes
