// Message conversions of the agent nodelets (the only place that knows both the
// ROS types and the core types).
#pragma once

#include <geometry_msgs/Pose.h>
#include <sensor_msgs/CameraInfo.h>
#include <sensor_msgs/Image.h>

#include <string>

#include "hermes/agent/camera_stream.h"
#include "hermes/core/camera_calibration.h"
#include "hermes/core/geometry.h"
#include "hermes/core/map_types.h"
#include "hermes/core/status.h"

namespace hermes_agent {

/// CameraInfo of a rectified camera; `baseline` > 0 fills the right camera's Tx.
sensor_msgs::CameraInfo infoFromIntrinsics(const hermes::PinholeIntrinsics& K, double baseline,
                                           const std::string& frame_id);
/// The fields of a CameraInfo for the core's checks (cameraInfoFromMessage).
hermes::CameraInfoMessage cameraInfoMessage(const sensor_msgs::CameraInfo& info);
/// The image as the core takes it: a view of the message's pixels (kept alive
/// by InputImage::owner), its stamp and encoding. Pixels of an encoding
/// OpenCV has no type for are viewed as bytes (the core then names the
/// encoding as unsupported); big-endian 16/32-bit pixels are copied swapped.
/// Error: the data is shorter than step x height, or step < width x pixel size.
hermes::Expected<hermes::agent::InputImage> inputImage(const sensor_msgs::ImageConstPtr& msg);
geometry_msgs::Pose toPose(const hermes::SE3& T);

}  // namespace hermes_agent
