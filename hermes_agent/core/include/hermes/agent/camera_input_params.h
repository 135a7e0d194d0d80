// Parameters of the camera input (camera_input.h), config section camera_input.
// Apart from camera_input.h so that RunParams (run_config.h) can hold them.
#pragma once

#include <string>

#include "hermes/core/config.h"
#include "hermes/core/status.h"

namespace hermes::agent {

/// Section camera_input.
struct CameraInputParams {
  /// Stereo images: "auto" (as the calibration's `rectified` says), "raw"
  /// (rectify here; a rectified camera_info calibration then uses its raw
  /// cameras) or "rectified" (needs a rectified calibration).
  std::string stereo_images = "auto";
  double rectify_alpha = 0.0;  ///< raw stereo: 0 keeps valid pixels only, 1 every pixel
  /// 16UC1 depth value per metre; 0 = the calibration's depth_scale (TUM PNG
  /// 5000). ROS RGB-D drivers publish millimetres: 1000.
  double depth_scale_16u = 0.0;
  double stereo_slop = 0.001;  ///< [s] largest left/right stamp difference
  double rgbd_slop = 0.020;    ///< [s] largest colour/depth stamp difference
  int sync_capacity = 10;      ///< messages waiting per stream for a partner

  Status read(const Config& config, const std::string& prefix = "camera_input");
  void write(ConfigWriter* writer, const std::string& prefix = "camera_input") const;
  Status validate() const;
};

}  // namespace hermes::agent
