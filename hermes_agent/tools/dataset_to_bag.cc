// hermes_dataset_to_bag: writes an EuRoC (stereo) or TUM/ICL-NUIM (RGB-D) folder
// into a rosbag with the topics the Agent nodelet subscribes to, so a recorded
// sequence can be replayed with `rosbag play` instead of the DatasetPlayer:
//   stereo: <ns>/left/image_rect, <ns>/right/image_rect (mono8, rectified),
//           <ns>/left/camera_info, <ns>/right/camera_info
//   rgbd  : <ns>/rgb/image_rect (mono8), <ns>/depth/image_rect (32FC1 [m]), <ns>/rgb/camera_info
// Stamps are the dataset's. Exit: 0 ok, 1 write failure, 2 bad input.
#include <cv_bridge/cv_bridge.h>
#include <rosbag/bag.h>
#include <sensor_msgs/image_encodings.h>

#include <cstdio>
#include <cstdlib>
#include <iostream>
#include <string>

#include "../src/ros_convert.h"
#include "hermes/agent/dataset_feed.h"

namespace {
const char* kUsage =
    "usage: hermes_dataset_to_bag --dataset DIR --out FILE.bag [--ns NAMESPACE] [--max-frames N]\n"
    "Writes DIR (EuRoC ASL stereo, rectified; or TUM RGB-D) as a rosbag with the Agent\n"
    "nodelet's topics under NAMESPACE (default agent0): left|right/image_rect + camera_info\n"
    "(stereo) or rgb/image_rect, depth/image_rect, rgb/camera_info (RGB-D).\n"
    "Replay: rosbag play FILE.bag, with `roslaunch hermes_agent agent.launch robot:=NAMESPACE`.\n";
}  // namespace

int main(int argc, char** argv) {
  std::string dir, out, ns = "agent0";
  long max_frames = 0;
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
    } else if (a == "--max-frames") {
      max_frames = std::atol(next().c_str());
    } else {
      std::fprintf(stderr, "hermes_dataset_to_bag: unknown argument '%s' (see --help)\n", a.c_str());
      return 2;
    }
  }
  if (dir.empty() || out.empty()) {
    std::fprintf(stderr, "hermes_dataset_to_bag: --dataset and --out are required (see --help)\n");
    return 2;
  }
  auto ds = hermes::Dataset::open(dir, hermes::DatasetParams{});
  if (!ds.ok()) {
    std::fprintf(stderr, "hermes_dataset_to_bag: dataset %s: %s\n", dir.c_str(), ds.error().c_str());
    return 2;
  }
  const hermes::DatasetInfo& info = (*ds)->info();
  const bool stereo = info.kind == hermes::DatasetKind::kEuroc;
  std::size_t n = info.frame_count;
  if (max_frames > 0 && std::size_t(max_frames) < n) n = std::size_t(max_frames);
  const std::string p = "/" + ns + "/";
  namespace enc = sensor_msgs::image_encodings;
  try {
    rosbag::Bag bag(out, rosbag::bagmode::Write);
    sensor_msgs::CameraInfo li = hermes_agent::infoFromIntrinsics(info.K, 0.0, ns + "/camera");
    sensor_msgs::CameraInfo ri = hermes_agent::infoFromIntrinsics(info.K, info.baseline, ns + "/camera_right");
    for (std::size_t i = 0; i < n; ++i) {
      auto f = hermes::loadCameraFrame(**ds, i);
      if (!f.ok()) {
        std::fprintf(stderr, "hermes_dataset_to_bag: frame %zu: %s\n", i, f.error().c_str());
        return 1;
      }
      std_msgs::Header h;
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
      if ((i + 1) % 100 == 0 || i + 1 == n) std::fprintf(stderr, "\rhermes_dataset_to_bag: %zu/%zu frames", i + 1, n);
    }
    bag.close();
  } catch (const std::exception& e) {
    std::fprintf(stderr, "\nhermes_dataset_to_bag: writing %s: %s\n", out.c_str(), e.what());
    return 1;
  }
  std::fprintf(stderr, "\nhermes_dataset_to_bag: wrote %s\n", out.c_str());
  return 0;
}
