// Camera images as a robot publishes them -> the CameraFrame the agent tracks.
// Created from a CameraCalibration (camera_calibration.h), a CameraInput gives
// the AgentCamera the pipeline must be created with and converts each image:
//   * stereo, raw (distorted) cameras: grey, then rectified with remap tables
//     built once (AgentCamera: the rectified K, baseline and T_B_Crect);
//   * stereo, rectified cameras: grey, as is (AgentCamera: the left K, the rig's
//     baseline, the left T_B_C); a right cx differing from the left one is
//     removed by shifting the right image, so disparity is 0 at infinity;
//   * RGB-D: colour -> grey, depth 16UC1 / 32FC1 -> CV_32F metres (NaN, inf,
//     0 and negative -> 0 = no depth); a distorted colour camera is undistorted
//     into its own K (colour bilinear, depth nearest-neighbour with the same
//     map, so the depth stays registered; pixels the lens does not see are
//     black / 0). AgentCamera: the colour K, the colour T_B_C.
// Bad images are returned as errors naming the cause; a counter per cause lets
// a node log each cause once and report how often it happened.
// Encodings are the ROS sensor_msgs/image_encodings names.
#pragma once

#include <cstdint>
#include <map>
#include <string>

#include <opencv2/core.hpp>

#include "hermes/agent/agent_pipeline.h"
#include "hermes/agent/approximate_sync.h"
#include "hermes/agent/camera_input_params.h"
#include "hermes/agent/tracker.h"
#include "hermes/core/camera_calibration.h"
#include "hermes/core/config.h"
#include "hermes/core/stereo_rig.h"

namespace hermes::agent {

/// A frame stamp as the camera errors print it: seconds, six decimals.
std::string stampText(double t_s);

class CameraInput {
 public:
  /// Errors: invalid params or calibration, a rig that cannot be rectified.
  static Expected<CameraInput> create(const CameraCalibration& calibration,
                                      const CameraInputParams& params = {});

  bool isStereo() const { return calib_.kind == CameraCalibration::Kind::kStereo; }
  /// The camera the pipeline must be created with (AgentPipeline::create).
  const AgentCamera& camera() const { return camera_; }
  /// The stream pairing for this camera: stereo_slop or rgbd_slop, sync_capacity.
  SyncParams syncParams() const;
  const CameraCalibration& calibration() const { return calib_; }
  /// The 16UC1 depth value per metre in use.
  double depthScale16u() const { return depth_scale_16u_; }
  /// One line for logs: kind, what is done to the images, the K handed out.
  std::string summary() const;

  /// A stereo pair in `encoding` (mono8/8UC1, bgr8, rgb8, bgra8, rgba8), both
  /// images of the calibration's size. The frame may share the pixels of
  /// mono8 inputs that need no rectification.
  Expected<CameraFrame> stereo(double stamp, const cv::Mat& left, const cv::Mat& right,
                               const std::string& encoding);
  /// A colour image (encodings as stereo()) and its depth image (16UC1 or
  /// mono16: value / depthScale16u() = metres; 32FC1: metres), both of the
  /// calibration's size; `stamp` is the colour stamp.
  Expected<CameraFrame> rgbd(double stamp, const cv::Mat& colour,
                             const std::string& colour_encoding, const cv::Mat& depth,
                             const std::string& depth_encoding);

  /// Rejected inputs per cause: "wrong camera kind", "bad stamp", "empty image",
  /// "unsupported encoding", "type does not match encoding", "size mismatch".
  const std::map<std::string, std::int64_t>& errorCounts() const { return errors_; }
  /// The cause of the last rejected input ("" before any).
  const std::string& lastErrorCause() const { return last_cause_; }
  /// True when the last error was the first of its cause: log it then.
  bool lastErrorIsNew() const;
  std::int64_t framesConverted() const { return converted_; }

 private:
  CameraInput() = default;
  Error fail(const std::string& cause, const std::string& message);
  Expected<cv::Mat> grey(const cv::Mat& image, const std::string& encoding,
                         const std::string& what);

  CameraCalibration calib_;
  CameraInputParams params_;
  AgentCamera camera_;
  bool rectify_ = false;       ///< stereo: remap with rect_
  RectifiedStereo rect_;
  double right_shift_px_ = 0;  ///< rectified stereo: cx_left - cx_right
  bool undistort_ = false;     ///< RGB-D: remap with map_x_/map_y_
  cv::Mat map_x_, map_y_;      ///< RGB-D undistortion (CV_32FC1)
  double depth_scale_16u_ = 0;
  std::map<std::string, std::int64_t> errors_;
  std::string last_cause_;
  std::int64_t converted_ = 0;
};

}  // namespace hermes::agent
