// Message conversions of the agent nodelets (the only place that knows both the
// ROS types and the core types).
#pragma once

#include <cv_bridge/cv_bridge.h>
#include <geometry_msgs/Pose.h>
#include <sensor_msgs/CameraInfo.h>
#include <sensor_msgs/Image.h>

#include <string>

#include "hermes/core/map_types.h"
#include "hermes/core/geometry.h"
#include "hermes/core/status.h"

namespace hermes_agent {

/// Rectified pinhole camera of a CameraInfo (from its P matrix); error when unusable.
hermes::Expected<hermes::PinholeIntrinsics> intrinsicsFromInfo(const sensor_msgs::CameraInfo& info);
/// Stereo baseline [m] from the right camera's P (P[3] = -fx * b).
double baselineFromInfo(const sensor_msgs::CameraInfo& right);
/// CameraInfo of a rectified camera; `baseline` > 0 fills the right camera's Tx.
sensor_msgs::CameraInfo infoFromIntrinsics(const hermes::PinholeIntrinsics& K, double baseline,
                                           const std::string& frame_id);
/// 8-bit grey view of a mono8/bgr8/rgb8 image; error names the encoding.
hermes::Expected<cv::Mat> greyImage(const sensor_msgs::ImageConstPtr& msg);
/// Depth in metres (32FC1, or 16UC1 millimetres converted).
hermes::Expected<cv::Mat> depthImage(const sensor_msgs::ImageConstPtr& msg);
geometry_msgs::Pose toPose(const hermes::SE3& T);

}  // namespace hermes_agent
