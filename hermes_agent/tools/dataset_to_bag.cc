// hermes_dataset_to_bag: writes an EuRoC (stereo) or TUM/ICL-NUIM (RGB-D) folder
// into a rosbag, in one of three topic layouts:
//   hermes: what the DatasetPlayer publishes (rectified, with camera_info):
//           stereo: <ns>/left/image_rect, <ns>/right/image_rect (mono8),
//                   <ns>/left/camera_info, <ns>/right/camera_info
//           rgbd  : <ns>/rgb/image_rect (mono8, as loaded: a TUM fr1/fr2 colour image
//                   keeps its distortion, which rgb/camera_info's D carries),
//                   <ns>/depth/image_rect (32FC1 [m]), <ns>/rgb/camera_info
//   euroc : as the published EuRoC bags: /cam0/image_raw, /cam1/image_raw, the
//           raw (distorted) mono8 images of the folder, no camera_info
//   tum   : as the published TUM RGB-D bags: /camera/rgb/image_color (rgb8),
//           /camera/depth/image (32FC1 [m]), no camera_info; the depth stamps
//           are the folder's, moved by up to --depth-offset-ms so that colour
//           and depth are not synchronised (a rendered folder stamps them alike)
// Stamps are the dataset's. Exit: 0 ok, 1 write failure, 2 bad input.
#include <cv_bridge/cv_bridge.h>
#include <rosbag/bag.h>
#include <sensor_msgs/image_encodings.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <iostream>
#include <string>

#include <opencv2/imgproc.hpp>

#include "../src/ros_convert.h"
#include "hermes/agent/dataset_feed.h"
#include "hermes_help/hermes_dataset_to_bag.h"  // tools/help/hermes_dataset_to_bag.txt

namespace {
const char* const kUsage = hermes_help::kText;

int usageError(const std::string& msg) {
  std::fprintf(stderr, "hermes_dataset_to_bag: %s (see --help)\n", msg.c_str());
  return 2;
}

}  // namespace

int main(int argc, char** argv) {
  std::string dir, out, ns = "agent0", layout = "hermes";
  long max_frames = 0;
  double depth_offset_ms = 10;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto next = [&]() -> std::string {
      if (i + 1 >= argc) {
        std::fprintf(stderr, "hermes_dataset_to_bag: %s needs a value\n", a.c_str());
        std::exit(2);
      }
      return argv[++i];
    };
    if (a == "--help" || a == "-h") {
      std::cout << kUsage;
      return 0;
    } else if (a == "--dataset") {
      dir = next();
    } else if (a == "--out") {
      out = next();
    } else if (a == "--ns") {
      ns = next();
    } else if (a == "--layout") {
      layout = next();
    } else if (a == "--max-frames") {
      max_frames = std::atol(next().c_str());
    } else if (a == "--depth-offset-ms") {
      char* end = nullptr;
      const std::string v = next();
      depth_offset_ms = std::strtod(v.c_str(), &end);
      if (end == v.c_str() || *end != '\0' || !(depth_offset_ms >= 0 && depth_offset_ms < 1000))
        return usageError("--depth-offset-ms must be a number in [0, 1000), got '" + v + "'");
    } else {
      return usageError("unknown argument '" + a + "'");
    }
  }
  if (dir.empty() || out.empty()) return usageError("--dataset and --out are required");
  if (layout != "hermes" && layout != "euroc" && layout != "tum")
    return usageError("--layout must be hermes, euroc or tum, got '" + layout + "'");
  hermes::DatasetParams dp;
  dp.rectify = layout != "euroc";  // the EuRoC layout carries the raw images
  auto ds = hermes::Dataset::open(dir, dp);
  if (!ds.ok()) {
    std::fprintf(stderr, "hermes_dataset_to_bag: dataset %s: %s\n", dir.c_str(), ds.error().c_str());
    return 2;
  }
  const hermes::DatasetInfo& info = (*ds)->info();
  const bool stereo = hermes::isStereo(info.kind);
  if (layout == "euroc" && info.kind != hermes::DatasetKind::kEuroc)
    return usageError("--layout euroc needs an EuRoC (stereo) folder; " + dir + " is " +
                      hermes::toString(info.kind));
  if (layout == "tum" && stereo)
    return usageError("--layout tum needs a TUM (RGB-D) folder; " + dir + " is " +
                      hermes::toString(info.kind));
  std::size_t n = info.frame_count;
  if (max_frames > 0 && std::size_t(max_frames) < n) n = std::size_t(max_frames);
  const std::string p = "/" + ns + "/";
  namespace enc = sensor_msgs::image_encodings;
  try {
    rosbag::Bag bag(out, rosbag::bagmode::Write);
    sensor_msgs::CameraInfo li = hermes_agent::infoFromIntrinsics(info.K, 0.0, ns + "/camera");
    sensor_msgs::CameraInfo ri = hermes_agent::infoFromIntrinsics(info.K, info.baseline, ns + "/camera_right");
    if (!stereo && info.rgbd)  // the colour images are published as loaded: with their lens distortion
      li.D.assign(info.rgbd->dist.begin(), info.rgbd->dist.end());
    for (std::size_t i = 0; i < n; ++i) {
      std_msgs::Header h;
      if (layout == "euroc") {
        auto f = (*ds)->loadStereo(i);
        if (!f.ok()) {
          std::fprintf(stderr, "hermes_dataset_to_bag: frame %zu: %s\n", i, f.error().c_str());
          return 1;
        }
        h.stamp.fromNSec(static_cast<std::uint64_t>(f->stamp_ns));
        h.frame_id = "cam0";
        bag.write("/cam0/image_raw", h.stamp, cv_bridge::CvImage(h, enc::MONO8, f->left).toImageMsg());
        h.frame_id = "cam1";
        bag.write("/cam1/image_raw", h.stamp, cv_bridge::CvImage(h, enc::MONO8, f->right).toImageMsg());
      } else if (layout == "tum") {
        auto f = (*ds)->loadRgbd(i);
        if (!f.ok()) {
          std::fprintf(stderr, "hermes_dataset_to_bag: frame %zu: %s\n", i, f.error().c_str());
          return 1;
        }
        // A fixed pattern in [-max, max], max at most 40 % of the frame interval
        // so that the depth stream stays in stamp order.
        const double interval = i + 1 < info.frame_count ? (*ds)->frameTime(i + 1) - f->t
                                                          : (i > 0 ? f->t - (*ds)->frameTime(i - 1) : 1.0);
        const double max_s = std::min(depth_offset_ms * 1e-3, 0.4 * interval);
        const double offset = max_s * (double((i * 7) % 11) / 5.0 - 1.0);
        cv::Mat rgb;
        cv::cvtColor(f->rgb, rgb, cv::COLOR_BGR2RGB);
        h.stamp = ros::Time(f->t);
        h.frame_id = "openni_rgb_optical_frame";
        bag.write("/camera/rgb/image_color", h.stamp, cv_bridge::CvImage(h, enc::RGB8, rgb).toImageMsg());
        h.stamp = ros::Time(f->depth_t + offset);
        h.frame_id = "openni_depth_optical_frame";
        bag.write("/camera/depth/image", h.stamp, cv_bridge::CvImage(h, enc::TYPE_32FC1, f->depth_m).toImageMsg());
      } else {
        auto f = hermes::loadCameraFrame(**ds, i);
        if (!f.ok()) {
          std::fprintf(stderr, "hermes_dataset_to_bag: frame %zu: %s\n", i, f.error().c_str());
          return 1;
        }
        h.stamp = ros::Time(f->stamp);
        h.frame_id = li.header.frame_id;
        li.header.stamp = ri.header.stamp = h.stamp;
        if (stereo) {
          bag.write(p + "left/image_rect", h.stamp, cv_bridge::CvImage(h, enc::MONO8, f->left).toImageMsg());
          bag.write(p + "right/image_rect", h.stamp, cv_bridge::CvImage(h, enc::MONO8, f->right).toImageMsg());
          bag.write(p + "left/camera_info", h.stamp, li);
          bag.write(p + "right/camera_info", h.stamp, ri);
        } else {
          bag.write(p + "rgb/image_rect", h.stamp, cv_bridge::CvImage(h, enc::MONO8, f->left).toImageMsg());
          bag.write(p + "depth/image_rect", h.stamp, cv_bridge::CvImage(h, enc::TYPE_32FC1, f->depth).toImageMsg());
          bag.write(p + "rgb/camera_info", h.stamp, li);
        }
      }
      if ((i + 1) % 100 == 0 || i + 1 == n) std::fprintf(stderr, "\rhermes_dataset_to_bag: %zu/%zu frames", i + 1, n);
    }
    bag.close();
  } catch (const std::exception& e) {
    std::fprintf(stderr, "\nhermes_dataset_to_bag: writing %s: %s\n", out.c_str(), e.what());
    return 1;
  }
  std::fprintf(stderr, "\nhermes_dataset_to_bag: wrote %s (layout %s)\n", out.c_str(), layout.c_str());
  return 0;
}
