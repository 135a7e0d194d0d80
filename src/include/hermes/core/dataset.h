// The runner's one door to dataset folders: detects the layout (EuRoC ASL, TUM RGB-D,
// ICL-NUIM as published, KITTI odometry), describes it (DatasetInfo) and loads frame i.
#pragma once

#include <memory>
#include <optional>
#include <string>
#include <variant>
#include <vector>

#include "hermes/core/camera.h"
#include "hermes/core/config.h"
#include "hermes/core/dataset_frames.h"
#include "hermes/core/euroc_dataset.h"
#include "hermes/core/kitti_dataset.h"
#include "hermes/core/status.h"
#include "hermes/core/stereo_rig.h"
#include "hermes/core/trajectory.h"
#include "hermes/core/tum_dataset.h"

namespace hermes {

/// Dataset reading parameters (config section `dataset`).
struct DatasetParams {
  double tum_max_dt = 0.02;    ///< [s] rgb-depth association tolerance
  double tum_depth_scale = 0;  ///< depth PNG value per metre; 0 = camera.yaml or 5000
  bool rectify = true;         ///< EuRoC: hand out rectified stereo images
  double rectify_alpha = 0.0;  ///< OpenCV free scaling, 0 = no black borders

  Status read(const Config& cfg);  ///< keys dataset.*
  void write(ConfigWriter& w) const;
  Status validate() const;
};

/// kEuroc: raw stereo + calibration; kKitti: rectified stereo; kTum: RGB-D (TUM RGB-D
/// and ICL-NUIM).
enum class DatasetKind { kEuroc, kTum, kKitti };
const char* toString(DatasetKind k);
inline bool isStereo(DatasetKind k) { return k != DatasetKind::kTum; }

struct DatasetInfo {
  DatasetKind kind = DatasetKind::kEuroc;
  std::string root;             ///< the folder as given
  std::size_t frame_count = 0;  ///< stereo pairs / associated rgb-depth pairs
  std::string layout;           ///< euroc | tum | icl_nuim | kitti
  std::optional<StereoRig> stereo;        ///< EuRoC: raw cameras; KITTI: the rectified pair
  std::optional<RgbdCamera> rgbd;         ///< TUM: depth camera
  /// Intrinsics of the images handed out (rectified left for EuRoC when
  /// rectification is on, the raw left otherwise; the RGB-D camera for TUM).
  PinholeIntrinsics K;
  double baseline = 0;  ///< [m] rectified stereo baseline (EuRoC, KITTI), 0 for TUM
  /// Body <- tracked camera: rectified left camera (EuRoC, rectification on),
  /// raw left (EuRoC, off), camera.yaml's T_B_C (TUM), the identity (KITTI: the
  /// ground truth is the left camera's). Estimated camera
  /// trajectories map to body poses through its inverse.
  SE3 T_B_C;
  Trajectory groundtruth;  ///< body pose in the world; empty when absent
  double t_start = 0, t_end = 0;  ///< [s] first and last frame stamps
  std::vector<std::string> warnings;
  std::string summary() const;  ///< one line for logs
};

/// An opened dataset. Frame loading is lazy and const (thread-safe as far as
/// cv::imread is).
class Dataset {
 public:
  static Expected<std::unique_ptr<Dataset>> open(const std::string& dir,
                                                 const DatasetParams& params = {});

  const DatasetInfo& info() const { return info_; }
  std::size_t size() const { return info_.frame_count; }
  /// Stamp of frame i [s] without loading images.
  double frameTime(std::size_t i) const;

  /// EuRoC (rectified when params.rectify) and KITTI (rectified as published): pair i.
  Expected<StereoFrame> loadStereo(std::size_t i) const;
  /// TUM only: frame i.
  Expected<RgbdFrame> loadRgbd(std::size_t i) const;

  /// EuRoC: the rectification (null for TUM or when rectification is off).
  const RectifiedStereo* rectification() const {
    return rectified_ ? &*rectified_ : nullptr;
  }
  const EurocDataset* euroc() const { return std::get_if<EurocDataset>(&data_); }
  const TumDataset* tum() const { return std::get_if<TumDataset>(&data_); }
  const KittiDataset* kitti() const { return std::get_if<KittiDataset>(&data_); }
  /// True when loadStereo() hands out rectified images (KITTI, or EuRoC rectified here).
  bool stereoRectified() const { return rectified_.has_value() || kitti() != nullptr; }

 private:
  Dataset() = default;
  DatasetInfo info_;
  std::variant<EurocDataset, TumDataset, KittiDataset> data_;
  std::optional<RectifiedStereo> rectified_;
};

/// Detects the layout of `dir` and describes it (this opens the dataset, so
/// list and calibration errors surface here).
Expected<DatasetInfo> probeDataset(const std::string& dir, const DatasetParams& params = {});

/// Layout detection only: kEuroc when DIR/mav0/cam0 or DIR/cam0 holds a data.csv,
/// kTum when DIR holds rgb.txt and depth.txt (TUM) or associations.txt (ICL-NUIM),
/// kKitti when DIR holds image_0/, image_1/ and calib.txt; otherwise an error naming
/// DIR and every layout looked for.
Expected<DatasetKind> detectDatasetKind(const std::string& dir);

}  // namespace hermes
