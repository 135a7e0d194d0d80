// The robot's borrowed map (DESIGN "Maps that last and flow back"): what the
// server's downlink sends it of the global map around it (core/map_down.h) -
// keyframes and landmarks that other trajectories mapped - held in the WORLD
// frame, so that a camera frame can be placed in the world from them alone.
// That is what a robot needs after a tracking loss: the new session's odometry
// frame is new and unknown to the server, but a PnP RANSAC of the frame's
// keypoints against borrowed landmarks gives T_W_C directly, and with it the
// new session's T_W_O.
//
// Packets. A packet's poses are in the odometry frame O of the session it
// names and it carries T_W_O, so each is converted when it is taken
// (T_W_C = T_W_O * T_O_C, p_W = T_W_O * p_O) and the session no longer
// matters. Packets are taken once per (epoch, seq) (a resend is counted as a
// duplicate and changes nothing; the caller still acknowledges it). Keyframes
// and landmarks are held by their origin key on the server: a key held
// already is replaced by the newer copy, never counted twice.
//
// Bound. At most max_landmarks landmarks are held. Beyond it the landmarks
// farthest from the robot's last known world position (setRobotPosition();
// before one, the mean camera position of the newest packet) go first: the
// server sends the map around the robot, so what lies far behind it is what it
// is least likely to see again. A keyframe left without landmarks goes too.
//
// Relocalisation. Brute-force Hamming matching of the frame's descriptors to
// the candidate landmarks (all of them, or with search_radius_m and a position
// guess, those of borrowed keyframes near the guess), threshold and ratio
// test, each landmark used once (the closer descriptor wins), then
// estimatePose() (pose_estimation.h). Cost: frame keypoints x candidates
// descriptor distances.
//
// Not thread-safe: the caller serialises ingest() and setRobotPosition()
// against everything else; const calls may run together.
#pragma once

#include <cstddef>
#include <cstdint>
#include <map>
#include <optional>
#include <set>
#include <string>
#include <vector>

#include "hermes/agent/pose_estimation.h"
#include "hermes/core/config.h"
#include "hermes/core/geometry.h"
#include "hermes/core/map_down.h"
#include "hermes/core/map_types.h"
#include "hermes/core/status.h"

namespace hermes::agent {

struct BorrowedMapParams {
  /// Landmarks held at most; beyond it those farthest from the robot go first
  /// (a keyframe left without landmarks goes with them).
  int max_landmarks = 4000;
  int max_hamming = 50;         ///< accept a descriptor match up to this distance [bits]
  double ratio = 0.8;           ///< best < ratio * second-best distance
  int min_inliers = 12;         ///< PnP inliers for a relocalisation to place the session
  /// With a position guess: only landmarks of borrowed keyframes whose camera
  /// lies within this distance of it are matched [m]; 0 = all landmarks.
  double search_radius_m = 0;
  /// Pixel sigma of a keypoint = this ^ octave: the ORB pyramid's scale_factor
  /// (not a key of its own: the pipeline sets it from orb.scale_factor).
  double octave_scale = 1.2;

  Status read(const Config& config, const std::string& prefix = "borrowed");
  void write(ConfigWriter* writer, const std::string& prefix = "borrowed") const;
  Status validate() const;
};

enum class IngestResult {
  kTaken,      ///< stored (then the bound enforced)
  kDuplicate,  ///< (epoch, seq) taken before: nothing changed, acknowledge it again
  kRefused,    ///< for another robot, or invalid: nothing changed, do not acknowledge
};

class BorrowedMap {
 public:
  /// params must pass validate() (checked).
  explicit BorrowedMap(const BorrowedMapParams& params);

  /// Takes a packet for robot `self`. kRefused (the reason in *why) when it is
  /// for another uuid or fails validate(); kDuplicate when its (epoch, seq)
  /// was taken before; else kTaken: every keyframe and landmark converted to
  /// the world frame and stored by origin key (replacing the one held), then
  /// the bound enforced. Keyframes without any landmark are not kept.
  IngestResult ingest(const MapDownPacket& packet, const Uuid& self, std::string* why = nullptr);

  /// The robot's world position [m], for the eviction rule (next ingest).
  void setRobotPosition(const Vec3& p_W) { robot_p_W_ = p_W; }

  struct Relocalisation {
    SE3 T_W_C;          ///< camera in the world
    int inliers = 0;    ///< PnP inliers
    int matches = 0;    ///< descriptor matches handed to PnP
    double rms_px = 0;  ///< RMS reprojection error of the inliers [px]
  };

  /// Places one camera frame in the world: `keypoints` undistorted, one
  /// descriptor each, intrinsics K, stereo baseline [m] (0 = none; with it a
  /// keypoint's depth > 0 adds its right-image column), an optional world
  /// position guess (used with search_radius_m > 0). Errors name why: the map
  /// is empty, no candidate near the guess, too few matches or inliers, input
  /// arrays differ in length.
  Expected<Relocalisation> relocalise(const std::vector<Keypoint>& keypoints,
                                      const std::vector<Descriptor>& descriptors,
                                      const PinholeIntrinsics& K, double baseline,
                                      const PoseEstimationParams& pose,
                                      const std::optional<Vec3>& guess_W = std::nullopt) const;

  std::size_t keyframes() const { return keyframes_.size(); }
  std::size_t landmarks() const { return lm_p_W_.size(); }
  /// World position of the landmark with this origin key, if held.
  std::optional<Vec3> landmark(const KeyframeKey& origin) const;
  /// World pose of the keyframe with this origin key, if held.
  std::optional<SE3> keyframePose(const KeyframeKey& origin) const;

  std::uint64_t packetsTaken() const { return packets_taken_; }
  std::uint64_t duplicates() const { return duplicates_; }
  std::uint64_t refused() const { return refused_; }
  std::uint64_t evicted() const { return evicted_landmarks_; }           ///< landmarks
  std::uint64_t evictedKeyframes() const { return evicted_keyframes_; }
  /// Estimate of the bytes the store holds: its arrays' capacities plus the
  /// tree nodes of its maps and sets (payload and typical node overhead).
  std::size_t memoryBytes() const;

  const BorrowedMapParams& params() const { return params_; }

 private:
  struct HeldKeyframe {
    double stamp = 0;
    SE3 T_W_C;
    std::vector<std::uint32_t> landmarks;  ///< indices into the landmark arrays
  };
  /// The seqs taken within one epoch: all of 1..contiguous, plus those above.
  struct TakenSeqs {
    std::uint64_t contiguous = 0;
    std::set<std::uint64_t> above;
    bool has(std::uint64_t seq) const { return seq <= contiguous || above.count(seq) > 0; }
    void add(std::uint64_t seq);
  };

  /// Drops the farthest landmarks beyond the bound and keyframes left without
  /// any; `centre_W` stands in for the robot position when none was set.
  void enforceBound(const Vec3& centre_W);
  /// Indices of the landmarks to match (all, or near the guess).
  std::vector<std::uint32_t> candidates(const std::optional<Vec3>& guess_W) const;

  BorrowedMapParams params_;
  // Landmarks as parallel flat arrays (matching reads the descriptors in order).
  std::vector<Vec3> lm_p_W_;
  std::vector<Descriptor> lm_desc_;
  std::vector<KeyframeKey> lm_key_;
  std::map<KeyframeKey, std::uint32_t> lm_index_;  ///< origin key -> array index
  std::map<KeyframeKey, HeldKeyframe> keyframes_;
  std::map<std::uint64_t, TakenSeqs> taken_;       ///< per epoch
  std::optional<Vec3> robot_p_W_;
  std::uint64_t packets_taken_ = 0, duplicates_ = 0, refused_ = 0;
  std::uint64_t evicted_landmarks_ = 0, evicted_keyframes_ = 0;
};

}  // namespace hermes::agent
