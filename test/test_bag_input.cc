// rostest: a rosbag in a published layout (EuRoC or TUM) is played at 1.0x into
// one Agent nodelet. Checks that the bag reached the agent whole, that at least
// ~min_tracked of its frames got an odometry pose (/R/odom), and the odometry
// against the rendered ground truth (ATE after SE(3) alignment, < ~max_ate).
// Prints and writes (~report, JSON) the numbers: frames, tracked, ATE, and the
// stamp-to-pose latency (odometry arrival minus the arrival of the same image
// at this test node, which subscribes to the first image topic too), the
// agent's per-stage timings (uplink_status) and the CPU its process used while
// the bag played (cores: /proc/<pid>/stat of the pid uplink_status names,
// sampled at each 1-Hz status between the first and the last frame).
#include <gtest/gtest.h>
#include <nav_msgs/Odometry.h>
#include <ros/ros.h>
#include <sensor_msgs/Image.h>
#include <std_msgs/String.h>

#include <unistd.h>

#include <algorithm>
#include <cstdint>
#include <fstream>
#include <iterator>
#include <map>
#include <mutex>
#include <sstream>
#include <vector>

#include <nlohmann/json.hpp>

#include "hermes/core/dataset.h"
#include "hermes/core/evaluation.h"

namespace {

struct Observed {
  std::mutex mu;
  std::map<std::int64_t, double> image_wall;  ///< image stamp [ns] -> arrival (wall) [s]
  std::map<std::int64_t, double> odom_wall;   ///< odometry stamp [ns] -> arrival [s]
  hermes::Trajectory odom;
  std::string status;
  double last_event = 0;  ///< wall time of the last image or odometry message
  /// CPU samples of the agent's process while frames flow: (wall [s], CPU [s]).
  std::vector<std::pair<double, double>> cpu;
};

/// User + system CPU time of a process [s]; < 0 when it cannot be read.
double processCpuSeconds(long pid) {
  std::ifstream f("/proc/" + std::to_string(pid) + "/stat");
  std::string text((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
  const std::size_t close = text.rfind(')');  // the command name may hold spaces
  if (close == std::string::npos) return -1;
  std::istringstream rest(text.substr(close + 2));
  std::string field;
  double utime = -1, stime = -1;
  for (int i = 3; i <= 15 && rest >> field; ++i) {  // fields 14, 15: utime, stime [ticks]
    if (i == 14) utime = std::stod(field);
    if (i == 15) stime = std::stod(field);
  }
  if (utime < 0 || stime < 0) return -1;
  return (utime + stime) / static_cast<double>(::sysconf(_SC_CLK_TCK));
}

double percentile(std::vector<double> v, double q) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  return v[std::min(v.size() - 1, static_cast<std::size_t>(q * double(v.size() - 1) + 0.5))];
}

}  // namespace

TEST(BagInput, OdometryFromAPublishedLayoutBag) {
  ros::NodeHandle nh, pnh("~");
  std::string data, robot = "R", image_topic, report;
  double max_ate = 0.05, min_tracked = 0.99;
  ASSERT_TRUE(pnh.getParam("data", data)) << "~data (rendered folder) is required";
  ASSERT_TRUE(pnh.getParam("image_topic", image_topic)) << "~image_topic is required";
  pnh.param("robot", robot, robot);
  pnh.param("max_ate", max_ate, max_ate);
  pnh.param("min_tracked", min_tracked, min_tracked);
  pnh.param("report", report, report);
  double timeout_s = 120;  // wall time allowed for the whole bag
  pnh.param("timeout_s", timeout_s, timeout_s);
  // A calibration from camera_info has no body frame: its odometry is the
  // (rectified) left / colour camera's, so the ground truth is taken there too.
  bool camera_frame = false;
  pnh.param("odometry_in_camera_frame", camera_frame, camera_frame);
  auto ds = hermes::Dataset::open(data, hermes::DatasetParams{});
  ASSERT_TRUE(ds.ok()) << ds.error();
  const std::size_t frames = (*ds)->info().frame_count;

  Observed o;
  ros::Subscriber image_sub = nh.subscribe<sensor_msgs::Image>(
      image_topic, 200, [&](const sensor_msgs::ImageConstPtr& m) {
        const double now = ros::WallTime::now().toSec();
        std::lock_guard<std::mutex> l(o.mu);
        o.image_wall[static_cast<std::int64_t>(m->header.stamp.toNSec())] = now;
        o.last_event = now;
      });
  ros::Subscriber odom_sub = nh.subscribe<nav_msgs::Odometry>(
      "/" + robot + "/odom", 1000, [&](const nav_msgs::OdometryConstPtr& m) {
        const double now = ros::WallTime::now().toSec();
        const auto& q = m->pose.pose.orientation;
        const auto& p = m->pose.pose.position;
        std::lock_guard<std::mutex> l(o.mu);
        o.odom_wall[static_cast<std::int64_t>(m->header.stamp.toNSec())] = now;
        o.odom.push_back(hermes::StampedPose{
            m->header.stamp.toSec(),
            hermes::SE3(hermes::Quat(q.w, q.x, q.y, q.z).normalized(), hermes::Vec3(p.x, p.y, p.z))});
        o.last_event = now;
      });
  ros::Subscriber status_sub = nh.subscribe<std_msgs::String>(
      "/" + robot + "/uplink_status", 5, [&](const std_msgs::StringConstPtr& s) {
        const double now = ros::WallTime::now().toSec();
        std::lock_guard<std::mutex> l(o.mu);
        o.status = s->data;
        // CPU while frames flow: from the first image on, until the odometry stops.
        if (o.image_wall.empty() || now - o.last_event > 1.0) return;
        const auto j = nlohmann::json::parse(s->data, nullptr, false);
        if (!j.is_object() || !j.contains("pid")) return;
        const double cpu = processCpuSeconds(j["pid"].get<long>());
        if (cpu >= 0) o.cpu.emplace_back(now, cpu);
      });
  ros::AsyncSpinner spinner(2);
  spinner.start();

  // Until every frame has a pose, or nothing arrived for 8 s after the first image.
  const ros::WallTime deadline = ros::WallTime::now() + ros::WallDuration(timeout_s);
  while (ros::WallTime::now() < deadline) {
    ros::WallDuration(0.5).sleep();
    std::lock_guard<std::mutex> l(o.mu);
    if (o.odom_wall.size() >= frames) break;
    if (!o.image_wall.empty() && ros::WallTime::now().toSec() - o.last_event > 8.0) break;
  }
  ros::WallDuration(1.5).sleep();  // the 1-Hz uplink_status after the last frame
  spinner.stop();
  std::lock_guard<std::mutex> l(o.mu);

  // Latency: odometry arrival - arrival of the same image here.
  std::vector<double> latency_ms;
  std::size_t exact = 0;  // odometry stamps equal to an image's header stamp to the nanosecond
  for (const auto& [stamp, wall] : o.odom_wall) {
    exact += o.image_wall.count(stamp);
    auto it = o.image_wall.lower_bound(stamp - 1000000);  // stamps round-trip through double
    if (it != o.image_wall.end() && std::llabs(it->first - stamp) <= 1000000)
      latency_ms.push_back(1e3 * (wall - it->second));
  }
  const double tracked = frames > 0 ? double(o.odom_wall.size()) / double(frames) : 0.0;
  std::printf("%s: %zu frames in the bag, %zu received here, %zu odometry poses (%.1f %%)\n",
              data.c_str(), frames, o.image_wall.size(), o.odom_wall.size(), 100 * tracked);
  std::printf("latency stamp->pose (vs. arrival here): median %.1f ms, p95 %.1f ms, max %.1f ms\n",
              percentile(latency_ms, 0.5), percentile(latency_ms, 0.95),
              percentile(latency_ms, 1.0));
  std::printf("uplink_status: %s\n", o.status.c_str());
  EXPECT_EQ(o.image_wall.size(), frames) << "the bag did not reach this node whole";
  EXPECT_GE(tracked, min_tracked) << "too few frames tracked";
  EXPECT_EQ(exact, o.odom_wall.size()) << "odometry not stamped with its image's stamp";

  nlohmann::json j;
  j["data"] = data;
  j["frames"] = frames;
  j["tracked"] = o.odom_wall.size();
  j["tracked_fraction"] = tracked;
  j["latency_ms"] = {{"median", percentile(latency_ms, 0.5)},
                     {"p95", percentile(latency_ms, 0.95)},
                     {"max", percentile(latency_ms, 1.0)}};
  const auto status = nlohmann::json::parse(o.status.empty() ? "{}" : o.status, nullptr, false);
  ASSERT_TRUE(status.is_object()) << o.status;
  ASSERT_TRUE(status.contains("frames")) << "uplink_status has no frame counts: " << o.status;
  const auto& f = status["frames"];
  EXPECT_EQ(f.value("tracked", -1), static_cast<std::int64_t>(o.odom_wall.size()))
      << "uplink_status counts other tracked frames than the odometry published";
  EXPECT_EQ(f.value("rejected", -1), 0) << f.dump();
  j["agent_frames"] = f;
  if (status.contains("timings_ms")) j["agent_timings_ms"] = status["timings_ms"];
  if (o.cpu.size() >= 2 && o.cpu.back().first > o.cpu.front().first) {
    j["cpu_cores"] = (o.cpu.back().second - o.cpu.front().second) /
                     (o.cpu.back().first - o.cpu.front().first);
    std::printf("agent process CPU while playing: %.2f cores\n", j["cpu_cores"].get<double>());
  }

  ASSERT_GE(o.odom.size(), 10u) << "too few poses to evaluate";
  const hermes::DatasetInfo& info = (*ds)->info();
  const hermes::Trajectory gt =
      camera_frame ? hermes::transformTrajectory(info.groundtruth, info.T_B_C) : info.groundtruth;
  auto ev = hermes::eval::evaluateTrajectory(gt, o.odom, hermes::eval::EvalParams{}, robot);
  ASSERT_TRUE(ev.ok()) << ev.error();
  std::printf("odometry ATE %.4f m (SE(3)-aligned) over %zu poses\n", ev->ate.trans_m.rmse,
              o.odom.size());
  j["ate_m"] = ev->ate.trans_m.rmse;
  EXPECT_LT(ev->ate.trans_m.rmse, max_ate);
  if (!report.empty()) std::ofstream(report) << j.dump(2) << "\n";
}

int main(int argc, char** argv) {
  testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "test_bag_input");
  return RUN_ALL_TESTS();
}
