// DatasetPlayer nodelet: publishes an EuRoC (stereo) or TUM/ICL-NUIM (RGB-D)
// folder so that no rosbag is needed for a demo. Images are what the core's
// Dataset hands out (EuRoC: rectified), with the dataset's stamps in the headers.
//   stereo: left/image_rect, right/image_rect (mono8), left/camera_info, right/camera_info
//   rgbd  : rgb/image_rect (mono8), depth/image_rect (32FC1 [m]), rgb/camera_info
//   done  : std_msgs/Empty (latched) after the last frame
// Params (private): dataset (folder, required), rate (x real time, 1.0),
// start_delay [s] (1.0; counted after the first subscriber appears), max_frames (0 = all).
#include <cv_bridge/cv_bridge.h>
#include <nodelet/nodelet.h>
#include <pluginlib/class_list_macros.hpp>
#include <ros/ros.h>
#include <sensor_msgs/image_encodings.h>
#include <std_msgs/Empty.h>

#include <atomic>
#include <thread>

#include "hermes/agent/dataset_feed.h"
#include "ros_convert.h"

namespace hermes_agent {

class DatasetPlayerNodelet : public nodelet::Nodelet {
 public:
  ~DatasetPlayerNodelet() override {
    stop_ = true;
    if (thread_.joinable()) thread_.join();
  }

 private:
  void onInit() override {
    ros::NodeHandle& nh = getNodeHandle();
    ros::NodeHandle& pnh = getPrivateNodeHandle();
    std::string dir;
    if (!pnh.getParam("dataset", dir)) {
      NODELET_FATAL("DatasetPlayer: parameter ~dataset (folder) is required");
      return;
    }
    pnh.param("rate", rate_, 1.0);
    pnh.param("start_delay", start_delay_, 1.0);
    pnh.param("max_frames", max_frames_, 0);
    if (!(rate_ > 0)) {
      NODELET_FATAL("DatasetPlayer: ~rate must be > 0, got %f", rate_);
      return;
    }
    auto ds = hermes::Dataset::open(dir, hermes::DatasetParams{});
    if (!ds.ok()) {
      NODELET_FATAL("DatasetPlayer: %s: %s", dir.c_str(), ds.error().c_str());
      return;
    }
    dataset_ = std::move(*ds);
    stereo_ = hermes::isStereo(dataset_->info().kind);
    if (stereo_) {
      left_ = nh.advertise<sensor_msgs::Image>("left/image_rect", 5);
      second_ = nh.advertise<sensor_msgs::Image>("right/image_rect", 5);
      left_info_ = nh.advertise<sensor_msgs::CameraInfo>("left/camera_info", 5);
      right_info_ = nh.advertise<sensor_msgs::CameraInfo>("right/camera_info", 5);
    } else {
      left_ = nh.advertise<sensor_msgs::Image>("rgb/image_rect", 5);
      second_ = nh.advertise<sensor_msgs::Image>("depth/image_rect", 5);
      left_info_ = nh.advertise<sensor_msgs::CameraInfo>("rgb/camera_info", 5);
    }
    done_ = nh.advertise<std_msgs::Empty>("done", 1, true);
    NODELET_INFO("DatasetPlayer: %s (%s) at %.2fx", dir.c_str(),
                 dataset_->info().summary().c_str(), rate_);
    thread_ = std::thread([this] { play(); });
  }

  void play() {
    const hermes::DatasetInfo& info = dataset_->info();
    while (!stop_ && ros::ok() && left_.getNumSubscribers() == 0) ros::WallDuration(0.05).sleep();
    ros::WallDuration(start_delay_).sleep();
    std::size_t n = info.frame_count;
    if (max_frames_ > 0 && std::size_t(max_frames_) < n) n = std::size_t(max_frames_);
    const std::string ns = getNodeHandle().getNamespace();
    const sensor_msgs::CameraInfo li = infoFromIntrinsics(info.K, 0.0, ns + "/camera");
    const sensor_msgs::CameraInfo ri = infoFromIntrinsics(info.K, info.baseline, ns + "/camera_right");
    const ros::WallTime start = ros::WallTime::now();
    const double t0 = dataset_->frameTime(0);
    for (std::size_t i = 0; i < n && !stop_ && ros::ok(); ++i) {
      const ros::WallTime due = start + ros::WallDuration((dataset_->frameTime(i) - t0) / rate_);
      const ros::WallTime now = ros::WallTime::now();
      if (due > now) (due - now).sleep();
      auto frame = hermes::loadCameraFrame(*dataset_, i);
      if (!frame.ok()) {
        NODELET_ERROR("DatasetPlayer: frame %zu: %s (skipped)", i, frame.error().c_str());
        continue;
      }
      std_msgs::Header h;
      h.stamp = ros::Time(frame->stamp);
      h.frame_id = li.header.frame_id;
      namespace enc = sensor_msgs::image_encodings;
      left_.publish(cv_bridge::CvImage(h, enc::MONO8, frame->left).toImageMsg());
      if (stereo_) {
        second_.publish(cv_bridge::CvImage(h, enc::MONO8, frame->right).toImageMsg());
      } else {
        second_.publish(cv_bridge::CvImage(h, enc::TYPE_32FC1, frame->depth).toImageMsg());
      }
      sensor_msgs::CameraInfo l = li, r = ri;
      l.header.stamp = r.header.stamp = h.stamp;
      left_info_.publish(l);
      if (stereo_) right_info_.publish(r);
    }
    done_.publish(std_msgs::Empty());
    NODELET_INFO("DatasetPlayer: finished (%zu frames)", n);
  }

  std::unique_ptr<hermes::Dataset> dataset_;
  bool stereo_ = true;
  double rate_ = 1.0, start_delay_ = 1.0;
  int max_frames_ = 0;
  ros::Publisher left_, second_, left_info_, right_info_, done_;
  std::thread thread_;
  std::atomic<bool> stop_{false};
};

}  // namespace hermes_agent

PLUGINLIB_EXPORT_CLASS(hermes_agent::DatasetPlayerNodelet, nodelet::Nodelet)
