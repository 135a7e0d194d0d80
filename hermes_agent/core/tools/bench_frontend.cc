// hermes_bench_frontend: timings of the visual front end on real EuRoC images.
//   ORB extraction per 752x480 frame (ours vs plain cv::ORB, same feature count),
//   CLAHE entropy, stereo matching on rectified pairs (cv::stereoRectify with the
//   sensor.yaml calibration), projection matching + PnP RANSAC + refinement of
//   every frame against the stereo landmarks of the first one (the drone sits
//   still in this clip, so the estimated motion is also a sanity figure), and the
//   whole stereo Tracker::feed per frame (its drift must stay near zero here).
//   Local bundle adjustment per keyframe (time, window size): on the real clip
//   (few keyframes: it hardly moves) and on a rendered moving sequence (the first
//   20 s of V1_01 from hermes_sim, rendered once into the cache folder).
// --ablation instead runs the keyframe-policy ablation (paper §IV-A): each
//   rendered sequence tracked with keyframe.policy entropy and covisibility;
//   keyframes, ATE, lost rate per run.
// Usage: tools/help/hermes_bench_frontend.txt (`hermes_bench_frontend --help`).
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <sstream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>
#include <opencv2/calib3d.hpp>
#include <opencv2/features2d.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "hermes/agent/feature_matching.h"
#include "hermes/agent/keyframe_policy.h"
#include "hermes/agent/orb_extractor.h"
#include "hermes/agent/pose_estimation.h"
#include "hermes/agent/stereo_matcher.h"
#include "hermes/agent/tracker.h"
#include "hermes/core/stopwatch.h"
#include "hermes_help/hermes_bench_frontend.h"  // tools/help/hermes_bench_frontend.txt
#include "rendered_runs.h"

using namespace hermes;
namespace fs = std::filesystem;

namespace {

using Clock = std::chrono::steady_clock;
/// Process CPU time [ms]: less sensitive than wall time to other jobs on the machine.
double cpuMs() { return 1000.0 * double(std::clock()) / CLOCKS_PER_SEC; }

nlohmann::json stats(std::vector<double> v) {
  nlohmann::json j;
  if (v.empty()) return j;
  std::sort(v.begin(), v.end());
  double sum = 0;
  for (double x : v) sum += x;
  j["median"] = v[v.size() / 2];
  j["p95"] = v[std::min(v.size() - 1, size_t(0.95 * v.size()))];
  j["mean"] = sum / v.size();
  j["n"] = v.size();
  return j;
}

/// Local bundle adjustment per keyframe: time and problem size of every solved window.
nlohmann::json localBaJson(const std::vector<LocalMappingStats>& mapping) {
  std::vector<double> ba, total, free_kf, fixed_kf, points, obs, res, iters;
  for (const LocalMappingStats& m : mapping) {
    total.push_back(m.total_ms);
    if (m.ba_ms <= 0) continue;  // BA off or degenerate window
    ba.push_back(m.ba_ms);
    free_kf.push_back(m.free_keyframes);
    fixed_kf.push_back(m.fixed_keyframes);
    points.push_back(m.points);
    obs.push_back(m.observations);
    res.push_back(m.residuals);
    iters.push_back(m.ba_iterations);
  }
  nlohmann::json j;
  j["keyframes_mapped"] = mapping.size();
  j["ba_ms"] = stats(ba);
  j["local_mapping_ms"] = stats(total);
  j["window"]["free_keyframes"] = stats(free_kf);
  j["window"]["fixed_keyframes"] = stats(fixed_kf);
  j["window"]["landmarks"] = stats(points);
  j["window"]["observations"] = stats(obs);
  j["window"]["residuals"] = stats(res);
  j["window"]["iterations"] = stats(iters);
  return j;
}

nlohmann::json runJson(const bench::SequenceRun& r) {
  nlohmann::json j;
  j["frames"] = r.frames;
  j["keyframes"] = r.keyframes;
  j["entropy_rule_keyframes"] = r.entropy_keyframes;
  j["entropy_only_keyframes"] = r.entropy_only_keyframes;
  j["landmarks"] = r.landmarks;
  j["lost_frames"] = r.lost;
  j["lost_rate"] = r.lostRate();
  if (r.ate_rmse_m >= 0) {
    j["ate_rmse_m"] = r.ate_rmse_m;
    j["ate_poses"] = r.ate_matched;
  } else {
    j["ate_rmse_m"] = nullptr;
    j["ate_error"] = r.ate_error;
  }
  j["tracker_feed_ms"] = stats(r.track_ms);
  j["tracker_feed_cpu_ms"] = stats(r.track_cpu_ms);
  j["keyframe_feed_cpu_ms"] = stats(r.keyframe_cpu_ms);
  if (!r.entropy_ratio.empty()) {  // where t_l / t_h sit in the frames' own spread
    std::vector<double> v = r.entropy_ratio;
    std::sort(v.begin(), v.end());
    auto q = [&](double f) { return v[std::min(v.size() - 1, std::size_t(f * double(v.size())))]; };
    j["entropy_ratio"] = {{"min", v.front()}, {"p01", q(0.01)}, {"p05", q(0.05)}, {"median", q(0.5)},
                          {"p95", q(0.95)}, {"p99", q(0.99)}, {"max", v.back()}, {"frames", v.size()}};
  }
  return j;
}

const std::string kTrajectories = std::string(HERMES_SOURCE_DIR) + "/config/trajectories";

/// The rendered moving sequence of the local-BA section.
const bench::RenderSpec kBaSequence{"V1_01_easy", 0, 20, 0.25, 1, {render::kPlainLook}};  // look of its published figures

/// Sequences of the keyframe-policy ablation: MH_01 in the default scene, and
/// V1_01 in the default scene and with most panels near-uniform (views swing
/// between rich and poor texture: 100..1000 ORB corners at 0.85).
const std::vector<bench::RenderSpec> kAblationSequences = {
    {"MH_01_easy", 0, 60, 0.25, 1},
    {"V1_01_easy", 0, 40, 0.25, 1},
    {"V1_01_easy", 0, 40, 0.7, 1},
    {"V1_01_easy", 0, 40, 0.85, 1},
};

int writeJson(const nlohmann::json& j, const std::string& json_out) {
  const std::string text = j.dump(2);
  std::cout << text << "\n";
  if (!json_out.empty()) {
    std::ofstream out(json_out);
    if (!out) {
      std::cerr << "hermes_bench_frontend: cannot write " << json_out << "\n";
      return 1;
    }
    out << text << "\n";
  }
  return 0;
}

/// "STEM,START,DURATION,POOR_FRACTION" (e.g. V1_01_easy,0,40,0.85) as a RenderSpec.
Expected<bench::RenderSpec> parseSequence(const std::string& text) {
  bench::RenderSpec s;
  std::stringstream ss(text);
  std::string stem, a, b, c;
  if (!std::getline(ss, stem, ',') || !std::getline(ss, a, ',') || !std::getline(ss, b, ',') ||
      !std::getline(ss, c) || stem.empty())
    return Error{"--sequence wants STEM,START,DURATION,POOR_FRACTION, got '" + text + "'"};
  try {
    s.stem = stem;
    s.start_s = std::stod(a);
    s.duration_s = std::stod(b);
    s.poor_fraction = std::stod(c);
  } catch (const std::exception&) {
    return Error{"--sequence: not a number in '" + text + "'"};
  }
  if (!(s.start_s >= 0 && s.duration_s > 0 && s.poor_fraction >= 0 && s.poor_fraction <= 1))
    return Error{"--sequence '" + text + "': need START >= 0, DURATION > 0, POOR_FRACTION in [0, 1]"};
  return s;
}

/// Keyframe-policy ablation over `sequences`.
int runAblation(const std::vector<bench::RenderSpec>& sequences, const std::string& cache,
                const std::string& json_out, const KeyframePolicyParams& keyframe) {
  nlohmann::json j;
  j["benchmark"] = "frontend_ablation";
  j["note"] =
      "stereo Tracker (default TrackerParams) on rendered EuRoC-layout sequences; only "
      "keyframe.policy differs; ATE: RMSE of the body trajectory of the tracked frames after "
      "SE(3) alignment; lost rate: frames not tracked / frames";
  j["runs"] = nlohmann::json::array();
  for (const bench::RenderSpec& spec : sequences) {
    auto dir = bench::renderCached(spec, cache, kTrajectories);
    if (!dir.ok()) {
      std::cerr << "hermes_bench_frontend: " << dir.error() << "\n";
      return 1;
    }
    for (const char* policy : {"entropy", "covisibility"}) {
      TrackerParams p;
      p.keyframe = keyframe;
      p.keyframe.policy = policy;
      std::fprintf(stderr, "[bench frontend] ablation: %s, policy %s\n", spec.describe().c_str(),
                   policy);
      auto r = bench::trackDataset(*dir, p);
      if (!r.ok()) {
        std::cerr << "hermes_bench_frontend: " << r.error() << "\n";
        return 1;
      }
      nlohmann::json row = runJson(*r);
      row["sequence"] = spec.describe();
      row["poor_fraction"] = spec.poor_fraction;
      row["policy"] = policy;
      row["dataset"] = *dir;
      row["render_settings"] = spec.settings;
      row["entropy_thresholds"] = {{"t_l", keyframe.ratio_low}, {"t_h", keyframe.ratio_high},
                                   {"fifo", keyframe.entropy_window}};
      row["local_ba_ms"] = localBaJson(r->mapping)["ba_ms"];
      j["runs"].push_back(row);
    }
  }
  return writeJson(j, json_out);
}

bool argv_has_entropy(int argc, char** argv) {
  for (int i = 1; i < argc; ++i)
    if (std::string(argv[i]) == "--entropy") return true;
  return false;
}

struct CamCalib {
  cv::Matx33d K;
  cv::Vec4d dist;
  cv::Matx44d T_B_C;
  cv::Size size;
};

Expected<CamCalib> readSensorYaml(const std::string& path) {
  cv::FileStorage f;
  try {
    if (!f.open(path, cv::FileStorage::READ)) return Error{"cannot open " + path};
  } catch (const cv::Exception& e) {
    return Error{"cannot parse " + path + ": " + e.what()};
  }
  std::vector<double> in, d, T, res;
  f["intrinsics"] >> in;
  f["distortion_coefficients"] >> d;
  f["T_BS"]["data"] >> T;
  f["resolution"] >> res;
  if (in.size() != 4 || d.size() != 4 || T.size() != 16 || res.size() != 2)
    return Error{path + ": intrinsics/distortion_coefficients/T_BS/resolution malformed"};
  CamCalib c;
  c.K = cv::Matx33d(in[0], 0, in[2], 0, in[1], in[3], 0, 0, 1);
  c.dist = cv::Vec4d(d[0], d[1], d[2], d[3]);
  for (int i = 0; i < 16; ++i) c.T_B_C(i / 4, i % 4) = T[i];
  c.size = cv::Size(int(res[0]), int(res[1]));
  return c;
}

std::vector<std::string> listPngs(const fs::path& dir) {
  std::vector<std::string> out;
  std::error_code ec;
  for (const auto& e : fs::directory_iterator(dir, ec))
    if (e.path().extension() == ".png") out.push_back(e.path().filename().string());
  std::sort(out.begin(), out.end());
  return out;
}

}  // namespace

int main(int argc, char** argv) {
  // Real data: the shipped EuRoC clip (data/README.md).
  std::string data = std::string(HERMES_DATA_DIR) + "/euroc_V1_01_micro/mav0";
  std::string json_out;
  std::string cache = "/tmp/hermes_bench_frontend";
  bool render = true, ablation = false;
  std::string look;  // --realistic | --plain (the ablation's renders; default realistic)
  KeyframePolicyParams keyframe;
  std::vector<bench::RenderSpec> sequences;
  int max_frames = 1000;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--help" || a == "-h") {
      std::cout << hermes_help::kText;
      return 0;
    } else if (a == "--cache" && i + 1 < argc) {
      cache = argv[++i];
    } else if (a == "--no-render") {
      render = false;
    } else if (a == "--ablation") {
      ablation = true;
    } else if (a == "--realistic" || a == "--plain") {
      if (!look.empty() && look != a) {
        std::cerr << "hermes_bench_frontend: --realistic and --plain exclude each other\n";
        return 2;
      }
      look = a;
    } else if (a == "--entropy" && i + 1 < argc) {
      const std::string v = argv[++i];
      if (std::sscanf(v.c_str(), "%lf,%lf,%d", &keyframe.ratio_low, &keyframe.ratio_high,
                      &keyframe.entropy_window) != 3 || !keyframe.validate()) {
        std::cerr << "hermes_bench_frontend: --entropy wants T_L,T_H,K with T_L < 1 < T_H and K >= 1, got '"
                  << v << "'\n";
        return 2;
      }
    } else if (a == "--sequence" && i + 1 < argc) {
      auto spec = parseSequence(argv[++i]);
      if (!spec.ok()) {
        std::cerr << "hermes_bench_frontend: " << spec.error() << "\n";
        return 2;
      }
      sequences.push_back(*spec);
    } else if (a == "--data" && i + 1 < argc) {
      data = argv[++i];
    } else if (a == "--frames" && i + 1 < argc) {
      max_frames = std::atoi(argv[++i]);
    } else if (a == "--json" && i + 1 < argc) {
      json_out = argv[++i];
    } else {
      std::cerr << "hermes_bench_frontend: unknown argument '" << a << "' (see --help)\n";
      return 2;
    }
  }
  if (!sequences.empty() && !ablation) {
    std::cerr << "hermes_bench_frontend: --sequence belongs to --ablation\n";
    return 2;
  }
  if ((!look.empty() || argv_has_entropy(argc, argv)) && !ablation) {
    std::cerr << "hermes_bench_frontend: --realistic, --plain and --entropy belong to --ablation\n";
    return 2;
  }
  if (ablation) {
    std::vector<bench::RenderSpec> specs = sequences.empty() ? kAblationSequences : sequences;
    if (look == "--plain")
      for (bench::RenderSpec& s : specs) s.settings.push_back(render::kPlainLook);
    return runAblation(specs, cache, json_out, keyframe);
  }
  auto c0 = readSensorYaml(data + "/cam0/sensor.yaml");
  auto c1 = readSensorYaml(data + "/cam1/sensor.yaml");
  if (!c0.ok() || !c1.ok()) {
    std::cerr << "hermes_bench_frontend: " << (c0.ok() ? c1.error() : c0.error()) << "\n";
    return 1;
  }
  // Pairs: names present in both folders (cam1 lacks a few).
  auto n0 = listPngs(data + "/cam0/data"), n1 = listPngs(data + "/cam1/data");
  std::vector<std::string> names;
  std::set_intersection(n0.begin(), n0.end(), n1.begin(), n1.end(), std::back_inserter(names));
  if (int(names.size()) > max_frames) names.resize(max_frames);
  if (names.size() < 2) {
    std::cerr << "hermes_bench_frontend: fewer than 2 stereo pairs under " << data << "\n";
    return 1;
  }

  // Rectification from the calibration: T_C1_C0 = T_B_C1^-1 T_B_C0.
  const cv::Matx44d T_C1_C0 = c1->T_B_C.inv() * c0->T_B_C;
  const cv::Matx33d R(T_C1_C0(0, 0), T_C1_C0(0, 1), T_C1_C0(0, 2), T_C1_C0(1, 0), T_C1_C0(1, 1),
                      T_C1_C0(1, 2), T_C1_C0(2, 0), T_C1_C0(2, 1), T_C1_C0(2, 2));
  const cv::Vec3d t(T_C1_C0(0, 3), T_C1_C0(1, 3), T_C1_C0(2, 3));
  cv::Mat R1, R2, P1, P2, Q, m0x, m0y, m1x, m1y;
  cv::stereoRectify(c0->K, c0->dist, c1->K, c1->dist, c0->size, R, t, R1, R2, P1, P2, Q,
                    cv::CALIB_ZERO_DISPARITY, 0);
  cv::initUndistortRectifyMap(c0->K, c0->dist, R1, P1, c0->size, CV_32FC1, m0x, m0y);
  cv::initUndistortRectifyMap(c1->K, c1->dist, R2, P2, c1->size, CV_32FC1, m1x, m1y);
  PinholeIntrinsics K;
  K.fx = P1.at<double>(0, 0);
  K.fy = P1.at<double>(1, 1);
  K.cx = P1.at<double>(0, 2);
  K.cy = P1.at<double>(1, 2);
  K.width = c0->size.width;
  K.height = c0->size.height;
  const double baseline = -P2.at<double>(0, 3) / P2.at<double>(0, 0);

  OrbParams orb_params;
  OrbExtractor extractor(orb_params);
  auto cv_orb = cv::ORB::create(orb_params.num_features, float(orb_params.scale_factor),
                                orb_params.num_levels);
  KeyframePolicy policy;
  StereoParams stereo_params;
  ProjectionMatchParams match_params;
  PoseEstimationParams pose_params;

  Tracker tracker(TrackerParams(), K, baseline);
  std::vector<double> t_track, cpu_track, track_mm;
  int track_lost = 0, track_errors = 0;
  std::vector<double> cpu_ours, cpu_cv;
  std::vector<double> t_ours, t_cv, t_entropy, t_stereo, t_match, t_pnp, n_ours, n_cv,
      n_stereo, n_inliers, motion_mm, motion_deg, rms_px;
  std::vector<LandmarkView> landmarks;
  std::vector<LocalMappingStats> real_mapping;
  for (size_t f = 0; f < names.size(); ++f) {
    cv::Mat raw0 = cv::imread(data + "/cam0/data/" + names[f], cv::IMREAD_GRAYSCALE);
    cv::Mat raw1 = cv::imread(data + "/cam1/data/" + names[f], cv::IMREAD_GRAYSCALE);
    if (raw0.empty() || raw1.empty()) {
      std::cerr << "hermes_bench_frontend: cannot read pair " << names[f] << "\n";
      return 1;
    }
    auto t0 = Clock::now();
    double c0_ms = cpuMs();
    auto feats_raw = extractor.extract(raw0);
    t_ours.push_back(msSince(t0));
    cpu_ours.push_back(cpuMs() - c0_ms);
    if (!feats_raw.ok()) {
      std::cerr << "hermes_bench_frontend: " << feats_raw.error() << "\n";
      return 1;
    }
    n_ours.push_back(double(feats_raw->size()));
    std::vector<cv::KeyPoint> kps;
    cv::Mat desc;
    t0 = Clock::now();
    c0_ms = cpuMs();
    cv_orb->detectAndCompute(raw0, cv::noArray(), kps, desc);
    t_cv.push_back(msSince(t0));
    cpu_cv.push_back(cpuMs() - c0_ms);
    n_cv.push_back(double(kps.size()));
    t0 = Clock::now();
    policy.claheEntropy(raw0);
    t_entropy.push_back(msSince(t0));

    cv::Mat left, right;
    cv::remap(raw0, left, m0x, m0y, cv::INTER_LINEAR);
    cv::remap(raw1, right, m1x, m1y, cv::INTER_LINEAR);
    auto fl = extractor.extract(left);
    auto fr = extractor.extract(right);
    if (!fl.ok() || !fr.ok()) return 1;
    t0 = Clock::now();
    auto st = matchStereo(&*fl, *fr, K, baseline, stereo_params);
    t_stereo.push_back(msSince(t0));
    if (!st.ok()) {
      std::cerr << "hermes_bench_frontend: " << st.error() << "\n";
      return 1;
    }
    n_stereo.push_back(st->matched);

    CameraFrame frame;
    frame.stamp = 0.05 * double(f);
    frame.left = left;
    frame.right = right;
    t0 = Clock::now();
    c0_ms = cpuMs();
    auto tr = tracker.feed(frame);
    t_track.push_back(msSince(t0));
    cpu_track.push_back(cpuMs() - c0_ms);
    if (!tr.ok()) {
      ++track_errors;
    } else if (tr->status != TrackingStatus::kOk) {
      ++track_lost;
    } else {
      track_mm.push_back(1000.0 * tr->T_W_C.translation().norm());
    }
    if (tr.ok() && tr->new_keyframe && tracker.keyframes().size() > 1)
      real_mapping.push_back(tr->mapping);

    if (f == 0) {  // the first frame's stereo points are the map (W = C of frame 0)
      for (size_t i = 0; i < fl->size(); ++i) {
        const Keypoint& k = fl->keypoints[i];
        if (k.depth <= 0) continue;
        LandmarkView l;
        l.p_W = Vec3((k.u - K.cx) / K.fx * k.depth, (k.v - K.cy) / K.fy * k.depth, k.depth);
        l.descriptor = fl->descriptors[i];
        l.angle = fl->angles[i];
        landmarks.push_back(l);
      }
      continue;
    }
    t0 = Clock::now();
    KeypointGrid grid(fl->keypoints, K.width, K.height);
    auto match = matchByProjection(landmarks, SE3(), K, *fl, grid, match_params);
    t_match.push_back(msSince(t0));
    Correspondences c;
    for (size_t i = 0; i < match.size(); ++i) {
      if (match[i] < 0) continue;
      const Keypoint& k = fl->keypoints[match[i]];
      c.p_W.push_back(landmarks[i].p_W);
      c.uv.push_back(Vec2(k.u, k.v));
      c.sigma_px.push_back(fl->scales[k.octave]);
    }
    t0 = Clock::now();
    auto pose = estimatePose(c, K, pose_params);
    t_pnp.push_back(msSince(t0));
    if (pose.ok()) {
      n_inliers.push_back(pose->num_inliers);
      motion_mm.push_back(1000.0 * pose->T_C_W.translation().norm());
      motion_deg.push_back(rotationAngle(pose->T_C_W.rotation()) * 180.0 / M_PI);
      rms_px.push_back(pose->rms_px);
    }
  }

  nlohmann::json j;
  j["benchmark"] = "frontend";
  j["data"] = data;
  j["frames"] = names.size();
  j["image_size"] = {K.width, K.height};
  j["orb_features_requested"] = orb_params.num_features;
  j["timings_ms"]["orb_extract_hermes"] = stats(t_ours);
  j["timings_ms"]["orb_extract_cv_orb"] = stats(t_cv);
  j["cpu_ms"]["orb_extract_hermes"] = stats(cpu_ours);
  j["cpu_ms"]["orb_extract_cv_orb"] = stats(cpu_cv);
  j["timings_ms"]["clahe_entropy"] = stats(t_entropy);
  j["timings_ms"]["stereo_match"] = stats(t_stereo);
  j["timings_ms"]["projection_match"] = stats(t_match);
  j["timings_ms"]["pnp_ransac_refine"] = stats(t_pnp);
  j["features_hermes"] = stats(n_ours);
  j["features_cv_orb"] = stats(n_cv);
  j["stereo"]["baseline_m"] = baseline;
  j["stereo"]["fx_rectified"] = K.fx;
  j["stereo"]["matched_per_pair"] = stats(n_stereo);
  j["pose_vs_first_frame"]["landmarks"] = landmarks.size();
  j["pose_vs_first_frame"]["frames_with_pose"] = n_inliers.size();
  j["pose_vs_first_frame"]["inliers"] = stats(n_inliers);
  j["pose_vs_first_frame"]["rms_px"] = stats(rms_px);
  j["pose_vs_first_frame"]["translation_mm"] = stats(motion_mm);
  j["pose_vs_first_frame"]["rotation_deg"] = stats(motion_deg);
  j["timings_ms"]["tracker_feed_stereo"] = stats(t_track);
  j["cpu_ms"]["tracker_feed_stereo"] = stats(cpu_track);
  // The figure: a stereo frame's tracking time over one cv::ORB
  // extraction of one image. Wall time (the right image is extracted on a
  // second thread) and process CPU time (both threads counted).
  auto med = [&](const char* group, const char* key) {
    return j[group][key]["median"].get<double>();
  };
  if (!t_track.empty() && !t_cv.empty()) {
    j["ratio_to_cv_orb"]["wall_median"] =
        med("timings_ms", "tracker_feed_stereo") / med("timings_ms", "orb_extract_cv_orb");
    j["ratio_to_cv_orb"]["cpu_median"] =
        med("cpu_ms", "tracker_feed_stereo") / med("cpu_ms", "orb_extract_cv_orb");
  }
  j["tracker"]["lost_frames"] = track_lost;
  j["tracker"]["errors"] = track_errors;
  j["tracker"]["keyframes"] = tracker.keyframes().size();
  j["tracker"]["landmarks"] = tracker.landmarks().size();
  j["tracker"]["translation_from_start_mm"] = stats(track_mm);
  j["pose_vs_first_frame"]["note"] =
      "drone static in this clip (ground truth moves < 3 mm): these are estimation errors";
  j["local_ba"]["real_clip"] = localBaJson(real_mapping);
  j["local_ba"]["real_clip"]["note"] = "the drone hardly moves: few keyframes";
  if (render) {
    auto dir = bench::renderCached(kBaSequence, cache, kTrajectories);
    if (!dir.ok()) {
      std::cerr << "hermes_bench_frontend: " << dir.error() << " (--no-render skips it)\n";
      return 1;
    }
    auto run = bench::trackDataset(*dir, TrackerParams());
    if (!run.ok()) {
      std::cerr << "hermes_bench_frontend: " << run.error() << "\n";
      return 1;
    }
    nlohmann::json r = localBaJson(run->mapping);
    r["sequence"] = kBaSequence.describe();
    r["dataset"] = *dir;
    r["tracking"] = runJson(*run);
    j["local_ba"]["rendered"] = r;
  }
  return writeJson(j, json_out);
}
