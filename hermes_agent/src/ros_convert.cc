#include "ros_convert.h"

#include <cv_bridge/cv_bridge.h>

#include <algorithm>
#include <memory>

namespace hermes_agent {

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

hermes::CameraInfoMessage cameraInfoMessage(const sensor_msgs::CameraInfo& info) {
  hermes::CameraInfoMessage m;
  m.width = static_cast<int>(info.width);
  m.height = static_cast<int>(info.height);
  m.distortion_model = info.distortion_model;
  m.D = info.D;
  std::copy(info.K.begin(), info.K.end(), m.K.begin());
  std::copy(info.R.begin(), info.R.end(), m.R.begin());
  std::copy(info.P.begin(), info.P.end(), m.P.begin());
  return m;
}

hermes::Expected<hermes::agent::InputImage> inputImage(const sensor_msgs::ImageConstPtr& msg) {
  hermes::agent::InputImage in;
  in.stamp = msg->header.stamp.toSec();
  in.encoding = msg->encoding;
  in.owner = std::shared_ptr<const void>(msg.get(), [msg](const void*) {});  // holds the message
  int type = CV_8UC1;
  bool known = true;
  try {
    type = cv_bridge::getCvType(msg->encoding);
  } catch (const std::exception&) {  // no OpenCV type: the core reports the encoding
    known = false;
  }
  const std::size_t pixel = known ? CV_ELEM_SIZE(type) : 1;
  const std::size_t row = known ? std::size_t(msg->width) * pixel : msg->step;
  const std::string what = "image " + msg->encoding + " " + std::to_string(msg->width) + "x" +
                           std::to_string(msg->height) + " of frame '" + msg->header.frame_id + "'";
  if (msg->step < row || msg->data.size() < std::size_t(msg->step) * msg->height)
    return hermes::Error{what + ": step " + std::to_string(msg->step) + " and data size " +
                         std::to_string(msg->data.size()) + " do not hold its pixels"};
  const int cols = known ? static_cast<int>(msg->width) : static_cast<int>(msg->step);
  cv::Mat view(static_cast<int>(msg->height), cols, type,
               const_cast<std::uint8_t*>(msg->data.data()), msg->step);
  const std::size_t elem = CV_ELEM_SIZE1(type);
  if (known && msg->is_bigendian && elem > 1) {  // this host is little-endian
    cv::Mat swapped = view.clone();
    for (int y = 0; y < swapped.rows; ++y) {
      std::uint8_t* p = swapped.ptr<std::uint8_t>(y);
      for (std::size_t i = 0; i + elem <= swapped.cols * pixel; i += elem) std::reverse(p + i, p + i + elem);
    }
    in.image = swapped;
    in.owner.reset();
  } else {
    in.image = view;
  }
  return in;
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
