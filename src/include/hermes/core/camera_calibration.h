// Camera calibration files as robots and public datasets publish them, read
// into one plain-data CameraCalibration:
//   * Hermes camera files (config/cameras/NAME.yaml, format below);
//   * EuRoC sensor.yaml pairs (mav0/cam0 + mav0/cam1);
//   * Kalibr camchain.yaml / camchain-imucam.yaml (pinhole, radtan|equidistant);
//   * ROS camera_info YAML pairs (camera_calibration_parsers' format), and
//     camera_info messages from topics (CameraInfoMessage, checked alike);
//   * TUM / ICL-NUIM camera.yaml (tum_dataset.h), as an RGB-D calibration.
// Every error names the file and the key ("x.yaml:3: key 'left.intrinsics'
// must be 4 numbers (has 3)").
//
// Hermes camera file (stereo):
//   kind: stereo               # stereo | rgbd
//   resolution: [752, 480]     # width, height [px] (both cameras)
//   rate_hz: 20                # [Hz] (optional, 0 = unknown)
//   rectified: false           # optional; true: images are rectified already
//   left:                      # and `right:` alike
//     model: pinhole           # the only projection model
//     distortion_model: radtan # none | radtan (k1 k2 p1 p2) | plumb_bob (k1 k2 p1 p2 k3)
//                              # | rational_polynomial (k1 k2 p1 p2 k3 k4 k5 k6)
//                              # | equidistant (k1 k2 k3 k4)
//     intrinsics: [458.654, 457.296, 367.215, 248.375]  # fx, fy, cx, cy [px]
//     distortion: [-0.283, 0.074, 0.0002, 0.00002]      # as distortion_model says
//     T_B_C: [16 numbers]      # body <- camera, row-major 4x4 (optional: identity)
// Hermes camera file (RGB-D): kind: rgbd, resolution, rate_hz, depth_scale
// (depth PNG value per metre) and one `camera:` block as above whose
// distortion_model is none, radtan or plumb_bob (the colour camera).
#pragma once

#include <array>
#include <optional>
#include <string>
#include <vector>

#include "hermes/core/camera.h"
#include "hermes/core/status.h"
#include "hermes/core/stereo_rig.h"

namespace hermes {

/// A calibration as read from a file; plain data.
struct CameraCalibration {
  enum class Kind { kStereo, kRgbd };
  Kind kind = Kind::kStereo;

  /// kStereo: the cameras the images come from (each with its T_B_C). When
  /// `rectified` is true they are distortion-free pinhole cameras with the same
  /// fx, fy, cy, the right one at +baseline along the left camera's x axis:
  /// the images need no rectification. cx may differ between them (disparity
  /// at infinity = cx_left - cx_right).
  StereoRig stereo;
  bool rectified = false;
  /// ROS camera_info pairs only: the raw (distorted) cameras the published
  /// rectification was computed from (extrinsics recovered from R and P), for
  /// agents that receive image_raw; rectify(*raw_stereo) redoes it.
  std::optional<StereoRig> raw_stereo;

  /// kRgbd: the colour camera (K, plumb_bob distortion), depth scale, T_B_C.
  RgbdCamera rgbd;

  int width = 0, height = 0;  ///< image size [px]
  std::string format;  ///< "hermes", "euroc", "kalibr", "camera_info" or "tum"
  std::string source;  ///< the file(s) read

  /// Consistency of the values (sizes, focal lengths, baseline, rigid T_B_C,
  /// distortion model per kind); errors start with `source`.
  Status validate() const;
  /// One line for logs: kind, format, size, model, fx, baseline, source.
  std::string summary() const;
};

/// Finds and reads a calibration. `name_or_path` is a bare name (read as
/// cameras_dir/NAME.yaml), a file, or a folder: a EuRoC sequence / mav0 folder
/// (cam0/ and cam1/ holding sensor.yaml) or a folder with the camera_info pair
/// left.yaml + right.yaml. A file's format is detected by its keys: `kind`
/// (Hermes), `cam0` (Kalibr), `camera_matrix` (ROS camera_info: its partner is
/// found by swapping left/right in the file name), `T_BS` (EuRoC: the partner
/// is ../cam1/sensor.yaml), `fx` + `depth_scale` (a TUM / ICL-NUIM
/// camera.yaml; a TUM folder holding camera.yaml is read the same way).
/// Unknown formats are an error naming the file.
Expected<CameraCalibration> loadCameraCalibration(const std::string& name_or_path,
                                                  const std::string& cameras_dir);

/// Hermes camera file (format above).
Expected<CameraCalibration> readHermesCameraFile(const std::string& path);
/// Writes `calib` as a Hermes camera file (full precision); `comment` becomes
/// the first line(s), e.g. the source of the values.
Status writeHermesCameraFile(const std::string& path, const CameraCalibration& calib,
                             const std::string& comment);

/// EuRoC cam0/cam1 sensor.yaml pair (T_BS, intrinsics, radtan, resolution, rate).
Expected<CameraCalibration> readEurocCalibration(const std::string& cam0_yaml,
                                                 const std::string& cam1_yaml);

/// Kalibr camchain: cam0 and cam1 (more cameras are ignored); camera_model
/// pinhole, distortion_model radtan | equidistant | none. cam1's pose comes
/// from its T_cn_cnm1 (cam1 <- cam0). With cam0's T_cam_imu the body is the
/// IMU (T_B_C = T_cam_imu^-1), without it the body is cam0. Kalibr gives no
/// frame rate: rate_hz is 0.
Expected<CameraCalibration> readKalibrCamchain(const std::string& path);

/// One ROS camera_info YAML file.
struct CameraInfo {
  std::string camera_name;
  int width = 0, height = 0;
  Mat3 K = Mat3::Identity();
  std::string distortion_model;  ///< plumb_bob | rational_polynomial | equidistant
  std::vector<double> D;         ///< 0, 4 or 5 (plumb_bob), 8, or 4 (equidistant)
  Mat3 R = Mat3::Identity();     ///< rectified <- raw camera rotation
  Eigen::Matrix<double, 3, 4> P = Eigen::Matrix<double, 3, 4>::Zero();  ///< rectified projection
  PinholeRadtan camera;  ///< the raw camera: K, size, distortion (identity T_B_C, rate 0)
};
/// Reads one camera_info file (all keys but camera_name are required; an
/// empty D means no distortion).
Expected<CameraInfo> readCameraInfoYaml(const std::string& path);

/// The fields of a sensor_msgs/CameraInfo message, without ROS (the nodelet
/// copies them over; see hermes_agent/src/ros_convert.h).
struct CameraInfoMessage {
  int width = 0, height = 0;
  std::string distortion_model;  ///< "" with an empty D: uncalibrated, no distortion
  std::vector<double> D;
  std::array<double, 9> K{};   ///< row-major
  std::array<double, 9> R{};   ///< row-major; all zero (uncalibrated drivers) = identity
  std::array<double, 12> P{};  ///< row-major 3x4
};
/// A camera_info message checked by readCameraInfoYaml's rules; errors start
/// with `source` (e.g. the topic) and name the field by its YAML key
/// ("/cam0/camera_info: key 'camera_matrix' must be ...").
Expected<CameraInfo> cameraInfoFromMessage(const CameraInfoMessage& msg, const std::string& source);

/// A camera_info stereo pair. The right P must carry the baseline
/// (P[0][3] = -fx' b, b > 0): the result is `rectified` (the pinhole pair of the
/// P matrices; the body frame is the raw left camera) with `raw_stereo` set.
/// A pair without a baseline has no extrinsics and is an error.
Expected<CameraCalibration> readCameraInfoPair(const std::string& left_yaml,
                                               const std::string& right_yaml);
/// The same rules on two parsed camera_infos (files or messages); `left_source`
/// and `right_source` name them in errors and in CameraCalibration::source.
Expected<CameraCalibration> stereoFromCameraInfo(const CameraInfo& left, const CameraInfo& right,
                                                 const std::string& left_source,
                                                 const std::string& right_source);
/// An RGB-D calibration from the colour camera's camera_info: its raw K and
/// plumb_bob distortion (at most 5 coefficients) with `depth_scale` (16UC1
/// depth value per metre); the body frame is the colour camera.
Expected<CameraCalibration> rgbdFromCameraInfo(const CameraInfo& colour, double depth_scale,
                                               const std::string& source);
/// The calibration of a camera publishing camera_info messages: a stereo pair
/// when `right` is given (stereoFromCameraInfo), else an RGB-D colour camera
/// with `depth_scale` (rgbdFromCameraInfo). Each message is checked by
/// cameraInfoFromMessage; errors name the source (topic) and the field.
Expected<CameraCalibration> calibrationFromCameraInfo(const CameraInfoMessage& left,
                                                      const std::string& left_source,
                                                      const CameraInfoMessage* right,
                                                      const std::string& right_source,
                                                      double depth_scale);
/// A TUM / ICL-NUIM camera.yaml (tum_dataset.h's format) as an RGB-D calibration.
Expected<CameraCalibration> readTumCalibration(const std::string& camera_yaml);

}  // namespace hermes
