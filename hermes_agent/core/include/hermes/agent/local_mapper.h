// Local mapping on keyframe insertion (DESIGN.md §3): triangulation of the
// newest keyframe's unlinked keypoints against its covisible keyframes
// (epipolar distance, descriptor ratio test, parallax, positive depth and
// reprojection checks; midpoint of the two rays), fusion of duplicates (local
// landmarks projected into the newest keyframe: a close keypoint with a
// similar descriptor gains the observation, or, if it already has another
// landmark, the two merge into the one with more observations), windowed bundle
// adjustment over the newest keyframes (free) and their covisible older
// keyframes (fixed), removal of outlier observations, and culling of landmarks
// that are rarely found where they should be visible or that gathered too few
// observations a few keyframes after their creation. Culled landmarks stay in
// the tracker's vector as tombstones (no observations, no keypoint links) so
// ids remain indices; they never enter the local map again.
#pragma once

#include <cstdint>
#include <functional>
#include <optional>
#include <utility>
#include <vector>

#include "hermes/agent/bundle_adjustment.h"
#include "hermes/core/config.h"
#include "hermes/core/map_types.h"

namespace hermes {

struct LocalMapperParams {
  bool enable_ba = true;
  int ba_window = 10;           ///< newest keyframes optimised
  int max_fixed = 10;           ///< covisible older keyframes held fixed
  int min_shared = 15;          ///< shared landmarks for covisibility
  int cull_after_keyframes = 3; ///< check a landmark this many keyframes after creation
  int min_observations = 2;     ///< ... it must then have at least this many keyframe views
  double min_found_ratio = 0.25;///< found / predicted-visible below this = culled
  double virtual_baseline = 0.08;  ///< [m] turns RGB-D depth into a right-u residual
  int triangulation_keyframes = 4; ///< covisible keyframes searched for new points
  int max_hamming = 40;            ///< descriptor distance for a triangulation match
  double min_parallax_deg = 2.0;   ///< bearing angle needed to triangulate
  BundleAdjustmentParams ba;

  /// Keys under "mapping" (and "mapping.ba").
  Status read(const Config& config);
  void write(ConfigWriter* writer) const;
  Status validate() const;
};

struct LocalMappingStats {
  double ba_ms = 0;     ///< bundle adjustment (problem set-up, solve, outlier check); 0 = not run
  double total_ms = 0;  ///< the whole process() call: culling, triangulation, fusion, BA
  int free_keyframes = 0, fixed_keyframes = 0, points = 0;
  int observations = 0;  ///< BA residual blocks (one per keyframe observation in the window)
  int residuals = 0;     ///< scalar BA residuals (3 per stereo/depth observation, 2 per mono)
  int ba_iterations = 0; ///< Levenberg-Marquardt iterations of the solve
  int outliers_removed = 0, culled = 0;
  int fused = 0;  ///< duplicate landmarks merged + observations added by projection
  /// Landmarks triangulated across keyframes: (id, keypoint index in the newest keyframe).
  std::vector<std::pair<LandmarkId, std::uint32_t>> triangulated;
};

/// A windowed bundle adjustment cut out of the map (LocalMapper::cutBa): copies
/// of the window's keyframe poses, landmark positions and observations, so it can
/// be solved (solveLocalBa) on any thread while the map goes on changing, then
/// written back by LocalMapper::applyBa on the map's own thread.
struct LocalBaJob {
  BaProblem problem;
  std::vector<KeyframeId> pose_kf;   ///< map keyframe of each problem pose
  std::vector<LandmarkId> point_lm;  ///< map landmark of each problem point
  /// Map observation of each problem observation (found again by keyframe and
  /// keypoint when the outliers are removed: indices may have moved meanwhile).
  struct Ref {
    LandmarkId lm;
    KeyframeId keyframe;
    std::uint32_t keypoint;
  };
  std::vector<Ref> refs;
  KeyframeId newest = 0;       ///< the newest keyframe (free) when cut
  SE3 T_W_newest;              ///< its pose when cut
  std::size_t keyframes = 0;   ///< map sizes when cut: later ids were created after
  std::size_t landmarks = 0;
  BundleAdjustmentParams params;
  LocalMappingStats stats;     ///< problem size (set when cut), solve figures
  std::optional<BaSummary> summary;  ///< set by a successful solve
  std::function<void()> before_solve;  ///< test hook, run on the solving thread
};

/// Solves the job's problem in place (pure: touches nothing but the job).
void solveLocalBa(LocalBaJob* job);

class LocalMapper {
 public:
  LocalMapper(const LocalMapperParams& params, const PinholeIntrinsics& K, double baseline);

  /// Book-keeping the tracker reports: creation, and per tracked frame whether a
  /// local landmark projected into the image (visible) and was an inlier (found).
  void noteCreated(LandmarkId id, KeyframeId keyframe);
  void noteVisible(LandmarkId id, bool found);
  bool isBad(LandmarkId id) const { return id < bad_.size() && bad_[id]; }

  /// Runs after the newest keyframe (keyframes->back()) has been inserted.
  /// `scales` are the pyramid level scales (pixel sigma per octave).
  LocalMappingStats process(std::vector<Keyframe>* keyframes, std::vector<Landmark>* landmarks,
                            const std::vector<float>& scales);

  /// The parts of process() that change the map's structure (culling,
  /// triangulation, fusion) for the newest keyframe; fills culled, fused and
  /// triangulated of `stats`.
  void processStructure(std::vector<Keyframe>* keyframes, std::vector<Landmark>* landmarks,
                        const std::vector<float>& scales, LocalMappingStats* stats);
  /// The bundle adjustment window around the newest keyframe as a job (its
  /// stats hold the problem size); nullopt when BA is off or the map has fewer
  /// than two keyframes.
  std::optional<LocalBaJob> cutBa(const std::vector<Keyframe>& keyframes,
                                  const std::vector<Landmark>& landmarks,
                                  const std::vector<float>& scales) const;
  /// Writes a solved job back into the map: poses of its free keyframes,
  /// positions of its landmarks not culled since, removal of its outlier
  /// observations still present. Keyframes and landmarks created after the cut
  /// (ids >= job.keyframes / job.landmarks, not in the job) move with the newest
  /// keyframe's correction so they stay consistent with the adjusted window
  /// (none exist when the job is applied at once). Nothing happens when the
  /// solve failed. Fills ba_ms, ba_iterations and outliers_removed of `stats`.
  void applyBa(const LocalBaJob& job, std::vector<Keyframe>* keyframes,
               std::vector<Landmark>* landmarks, LocalMappingStats* stats);

  const LocalMapperParams& params() const { return params_; }

 private:
  void removeObservation(std::vector<Keyframe>* kfs, Landmark* l, std::size_t index);
  void cull(std::vector<Keyframe>* kfs, Landmark* l);
  void fuse(std::vector<Keyframe>* kfs, std::vector<Landmark>* lms,
            const std::vector<float>& scales, LocalMappingStats* st);
  void triangulate(std::vector<Keyframe>* kfs, std::vector<Landmark>* lms,
                   const std::vector<float>& scales, LocalMappingStats* st);

  LocalMapperParams params_;
  PinholeIntrinsics K_;
  double baseline_;
  std::vector<KeyframeId> origin_;
  std::vector<int> visible_, found_;
  std::vector<bool> bad_;
};

}  // namespace hermes
