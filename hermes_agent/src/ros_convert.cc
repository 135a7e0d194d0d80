#include "ros_convert.h"

#include <sensor_msgs/image_encodings.h>

#include <cmath>
#include <opencv2/imgproc.hpp>

namespace hermes_agent {
namespace enc = sensor_msgs::image_encodings;

hermes::Expected<hermes::PinholeIntrinsics> intrinsicsFromInfo(const sensor_msgs::CameraInfo& info) {
  hermes::PinholeIntrinsics K;
  K.fx = info.P[0];
  K.fy = info.P[5];
  K.cx = info.P[2];
  K.cy = info.P[6];
  K.width = static_cast<int>(info.width);
  K.height = static_cast<int>(info.height);
  if (!(K.fx > 0 && K.fy > 0) || K.width <= 0 || K.height <= 0)
    return hermes::Error{"camera_info of frame '" + info.header.frame_id +
                         "' has no usable projection matrix P or size"};
  return K;
}

double baselineFromInfo(const sensor_msgs::CameraInfo& right) {
  return right.P[0] > 0 ? -right.P[3] / right.P[0] : 0.0;
}

sensor_msgs::CameraInfo infoFromIntrinsics(const hermes::PinholeIntrinsics& K, double baseline,
                                           const std::string& frame_id) {
  sensor_msgs::CameraInfo info;
  info.header.frame_id = frame_id;
  info.width = static_cast<unsigned>(K.width);
  info.height = static_cast<unsigned>(K.height);
  info.distortion_model = "plumb_bob";
  info.D.assign(5, 0.0);
  info.K = {K.fx, 0, K.cx, 0, K.fy, K.cy, 0, 0, 1};
  info.R = {1, 0, 0, 0, 1, 0, 0, 0, 1};
  info.P = {K.fx, 0, K.cx, -K.fx * baseline, 0, K.fy, K.cy, 0, 0, 0, 1, 0};
  return info;
}

hermes::Expected<cv::Mat> greyImage(const sensor_msgs::ImageConstPtr& msg) {
  try {
    if (msg->encoding == enc::MONO8) return cv_bridge::toCvShare(msg)->image;
    if (msg->encoding == enc::BGR8 || msg->encoding == enc::RGB8)
      return cv_bridge::toCvCopy(msg, enc::MONO8)->image;
  } catch (const cv_bridge::Exception& e) {
    return hermes::Error{std::string("image conversion: ") + e.what()};
  }
  return hermes::Error{"image encoding '" + msg->encoding + "' is not mono8/bgr8/rgb8"};
}

hermes::Expected<cv::Mat> depthImage(const sensor_msgs::ImageConstPtr& msg) {
  try {
    if (msg->encoding == enc::TYPE_32FC1) return cv_bridge::toCvShare(msg)->image;
    if (msg->encoding == enc::TYPE_16UC1) {
      cv::Mat m;
      cv_bridge::toCvShare(msg)->image.convertTo(m, CV_32F, 1e-3);
      return m;
    }
  } catch (const cv_bridge::Exception& e) {
    return hermes::Error{std::string("depth conversion: ") + e.what()};
  }
  return hermes::Error{"depth encoding '" + msg->encoding + "' is not 32FC1/16UC1"};
}

geometry_msgs::Pose toPose(const hermes::SE3& T) {
  geometry_msgs::Pose p;
  p.position.x = T.translation().x();
  p.position.y = T.translation().y();
  p.position.z = T.translation().z();
  const hermes::Quat q = T.quat();
  p.orientation.x = q.x();
  p.orientation.y = q.y();
  p.orientation.z = q.z();
  p.orientation.w = q.w();
  return p;
}

}  // namespace hermes_agent
