// Stereo / RGB-D visual odometry front end, one door in: feed(). The first frame
// with enough depth initialises a local map of landmarks; every further frame is
// tracked by constant-velocity prediction, projection matching against the
// local map, robust motion-only pose optimisation (PnP RANSAC when the
// prediction fails or after a loss: relocalisation against the local map), and
// the keyframe policy decides when a new keyframe adds fresh depth landmarks.
// Each new keyframe runs the local-mapping stage (mapping_stage.h: culling,
// triangulation, fusion, windowed bundle adjustment, in the frame's step or with
// the BA on a mapper thread); the motion model follows what it moves. The
// window cut (window_cut.h) hands the map on to distillation, up to
// mappedKeyframes(): in parallel mapping the newest keyframe whose BA has been
// applied, a consistent point, as in synchronous mode.
#pragma once

#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "hermes/agent/feature_matching.h"
#include "hermes/agent/keyframe_policy.h"
#include "hermes/agent/local_mapper.h"
#include "hermes/agent/mapping_stage.h"
#include "hermes/agent/orb_extractor.h"
#include "hermes/agent/pose_estimation.h"
#include "hermes/agent/rgbd_depth.h"
#include "hermes/agent/stereo_matcher.h"
#include "hermes/agent/submap_window.h"
#include "hermes/core/config.h"
#include "hermes/core/map_types.h"
#include "hermes/distill/scores.h"

namespace hermes {

/// One synchronised camera frame: a rectified stereo pair (left + right) or an
/// RGB-D frame (left + depth in metres, CV_32F, registered to left).
struct CameraFrame {
  double stamp = 0;  ///< [s]
  cv::Mat left;      ///< 8-bit grey, rectified
  cv::Mat right;     ///< 8-bit grey, rectified; empty for RGB-D
  cv::Mat depth;     ///< CV_32F metres; empty for stereo
};

struct TrackerParams {
  OrbParams orb;
  StereoParams stereo;
  RgbdDepthParams rgbd;
  ProjectionMatchParams matching;
  PoseEstimationParams pose;
  KeyframePolicyParams keyframe;
  LocalMapperParams mapping;
  SubmapWindowParams window;
  int init_min_points = 60;       ///< depth keypoints needed to initialise
  int min_tracked = 25;           ///< inliers for tracking to count as OK
  /// A tracked frame with fewer inliers is weak (TrackingHealth; the distiller
  /// spends more of the budget on windows in trouble). 0 = never weak.
  int weak_tracked = 80;
  int local_map_keyframes = 6;    ///< landmarks of the last N keyframes form the local map
  /// Moving objects: a landmark observed by fewer keyframes than this is new and
  /// may sit on something that moves (a landmark made on a moving box is seen
  /// at a new place in the next frame). While at least min_tracked matches are
  /// on older landmarks, only those move the pose; the new ones are classified
  /// against it (and kept when they fit) but cannot pull it. Without this a
  /// textured mover as large in the image as the static scene drags the
  /// odometry along (README, "moving objects"). 0 = every landmark moves the pose.
  int trusted_observations = 3;
  /// > 0: the pose is also solved with every match, and that solution is kept
  /// unless it moves the landmarks' projections by at least this mean distance
  /// from the trusted-only one [px] (new landmarks then only count where they
  /// agree: in fast motion they are much of what constrains the pose). 0 = the
  /// trusted-only solution always (README, "Moving objects").
  double trusted_disagreement_px = 0;
  double relocalise_radius_px = 40;  ///< search radius when lost
  /// When lost and the projection search fails: match the landmarks of the last N
  /// keyframes to the frame by descriptor alone + PnP RANSAC (0 = off).
  int relocalise_keyframes = 30;
  /// Lost this long [s] (relocalisation failing every frame): the agent starts a new
  /// map, a new session the server ties to the old one by loops (0 = never).
  double reinit_after_s = 1.0;

  /// Reads sections orb, stereo, rgbd, matching, pose, keyframe, mapping, window and tracker.
  Status read(const Config& config);
  void write(ConfigWriter* writer) const;
  Status validate() const;
};

enum class TrackingStatus { kNotInitialised, kOk, kLost };
const char* toString(TrackingStatus s);

struct TrackResult {
  TrackingStatus status = TrackingStatus::kNotInitialised;
  SE3 T_W_C;                 ///< camera pose in the odometry frame (valid when kOk)
  int matched = 0;           ///< landmarks matched before optimisation
  int tracked = 0;           ///< inliers after optimisation
  bool new_keyframe = false;
  KeyframeDecision keyframe;
  LocalMappingStats mapping;  ///< filled when new_keyframe (T_W_C is then the optimised pose)
};

class Tracker {
 public:
  Tracker(const TrackerParams& params, const PinholeIntrinsics& K, double baseline);
  ~Tracker();
  Tracker(const Tracker&) = delete;
  Tracker& operator=(const Tracker&) = delete;

  /// Runs the local BA on a mapper thread (true) or inside feed() (false, the
  /// default: bit-identical to the synchronous pipeline). Call before the first
  /// frame. `before_solve` (test hook, may be empty) runs on the mapper thread
  /// before every solve, e.g. to hold the mapper back.
  void setParallelMapping(bool parallel, std::function<void()> before_solve = {});
  bool parallelMapping() const { return mapping_.parallel(); }
  /// Parallel mapping: waits for the running BA, applies it and runs the BA of
  /// the keyframes still waiting, until none waits (end of sequence / flush).
  /// No-op in synchronous mode.
  void finishMapping();
  /// Counters of the local mapping stage (both modes).
  MappingStageStats mappingStats() const { return mapping_.stats(); }
  /// Keyframes a window may hand out: all in synchronous mode, those up to the
  /// newest adjusted one in parallel mode.
  std::size_t mappedKeyframes() const;

  /// Processes one frame. Errors: malformed frame (empty, wrong type or size).
  Expected<TrackResult> feed(const CameraFrame& frame);

  const std::vector<Keyframe>& keyframes() const { return keyframes_; }
  const std::vector<Landmark>& landmarks() const { return landmarks_; }
  /// Per keyframe: tracking was lost between it and the previous one.
  const std::vector<char>& lostBefore() const { return lost_before_; }
  const PinholeIntrinsics& intrinsics() const { return K_; }
  TrackingStatus status() const { return status_; }
  bool isLandmarkBad(LandmarkId id) const { return mapping_.mapper().isBad(id); }

  /// Drops the map (keyframes, landmarks, mapping state) and starts
  /// again: the next frame that can initialise opens a new map whose first keyframe
  /// sits at T_W_C in the same odometry frame (the last known pose). Keyframe and
  /// landmark ids start again at 0 (a new session). Parallel mapping finishes first.
  void startNewMap(const SE3& T_W_C);
  /// Counts tracking as interrupted since the last keyframe (test hook: a
  /// relocalisation the caller simulates); the next keyframe's odometry edge
  /// is weakened as after a real loss.
  void markLost() { lost_since_keyframe_ = true; }
  /// Latest VO motion for the distiller (valid after two consecutive tracked
  /// frames; its health is the window cut's, window_cut.h).
  distill::MotionHint motionHint() const;
  /// Tracking health of the frames since the previous call (the window cut
  /// takes it with each window).
  distill::TrackingHealth takeWindowHealth();
  /// Tracking health since the start (all frames fed).
  const distill::TrackingHealth& totalHealth() const { return total_health_; }

 private:
  Status computeFeatures(const CameraFrame& frame, FeatureSet* features) const;
  bool initialise(const CameraFrame& frame, FeatureSet& features, TrackResult* result);
  void insertKeyframe(double stamp, const SE3& T_W_C, const FeatureSet& features,
                      const std::vector<int>& keypoint_landmark);
  /// Landmarks seen by the last `keyframes` keyframes (good ones only).
  std::vector<std::size_t> localMap(int keyframes) const;
  /// Per landmark id: observed by at least trusted_observations keyframes.
  std::vector<bool> trustedLandmarks(const std::vector<int>& ids) const;
  /// Motion-only refinement from the prediction: trusted landmarks only while
  /// min_tracked of them match (and, with trusted_disagreement_px, every match
  /// where the two solutions agree); every match otherwise.
  Expected<PoseEstimate> refineFromPrior(const Correspondences& c, const std::vector<int>& ids,
                                         const SE3& T_C_W_pred) const;
  void runLocalMapping(TrackResult* r, const std::vector<float>& scales);
  /// Parallel mapping: a finished BA enters the map; the motion model follows it.
  void pollMapping();

  TrackerParams params_;
  PinholeIntrinsics K_;
  double baseline_;
  OrbExtractor extractor_;
  KeyframePolicy policy_;
  TrackingStatus status_ = TrackingStatus::kNotInitialised;
  std::vector<Keyframe> keyframes_;
  std::vector<Landmark> landmarks_;
  std::vector<float> landmark_angle_;       ///< per landmark, last keypoint angle [deg]
  std::vector<KeyframeId> landmark_origin_; ///< keyframe that created it
  std::vector<char> lost_before_;           ///< per keyframe: tracking was lost since the previous one
  bool lost_since_keyframe_ = false;
  SE3 T_C_W_last_, T_C_W_prev_;             ///< last two tracked poses
  SE3 T_W_C_init_;                          ///< first keyframe's pose of a new map
  bool have_velocity_ = false;
  int reference_tracked_ = 0;
  MappingStage mapping_;
  double last_stamp_ = 0, prev_stamp_ = 0;
  void noteHealth(const TrackResult& r);
  distill::TrackingHealth health_;         ///< frames since the last takeWindowHealth()
  distill::TrackingHealth total_health_;
};

}  // namespace hermes
