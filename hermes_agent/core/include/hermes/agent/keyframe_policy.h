// Keyframe designation (DESIGN §3, paper §IV-A). Entropy rule: each frame is
// equalised with CLAHE, H = -sum_b p_b log2 p_b over its 256-bin histogram, a
// FIFO keeps the last k entropies and r = H / mean(FIFO); a keyframe is due when
// r leaves [t_l, t_h]. It is OR-ed with the covisibility rules (tracked-landmark
// ratio below a threshold, too many frames since the last keyframe) and only
// applies while tracking is healthy. Policy `covisibility` uses the latter alone.
#pragma once

#include <deque>
#include <string>

#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include "hermes/core/config.h"
#include "hermes/core/status.h"

namespace hermes {

struct KeyframePolicyParams {
  std::string policy = "entropy";  ///< entropy | covisibility  (key keyframe.policy)
  double clahe_clip = 2.0;         ///< CLAHE clip limit
  int clahe_tiles = 8;             ///< CLAHE tiles per side
  int entropy_window = 10;         ///< k, FIFO length [frames]
  double ratio_low = 0.97;         ///< t_l
  double ratio_high = 1.03;        ///< t_h
  double min_tracked_ratio = 0.9;  ///< tracked / landmarks of the reference keyframe
  int max_frames = 20;             ///< frames since the last keyframe (about 1 s at 20 Hz)
  int min_frames = 0;              ///< no keyframe sooner than this after the last one
  int min_tracked = 15;            ///< tracking counts as healthy from this many landmarks
  /// Fewer tracked landmarks than this -> keyframe (0 = off): the map must renew
  /// itself before fast motion leaves it behind.
  int few_tracked = 100;

  Status read(const Config& config, const std::string& prefix = "keyframe");
  void write(ConfigWriter* writer, const std::string& prefix = "keyframe") const;
  Status validate() const;
};

/// Shannon entropy [bits] of the 256-bin histogram of an 8-bit grey image
/// (NaN for an empty image or another type).
double imageEntropy(const cv::Mat& grey);

/// What the tracker knows about the current frame.
struct TrackingState {
  bool ok = true;               ///< tracking healthy (not lost, pose accepted)
  int tracked = 0;              ///< landmarks tracked in this frame
  int reference_tracked = 0;    ///< landmarks of the reference (last) keyframe
};

struct KeyframeDecision {
  bool insert = false;
  bool by_entropy = false, by_tracked_ratio = false, by_max_frames = false, by_few_tracked = false;
  double entropy = 0;  ///< CLAHE entropy of this frame [bits] (NaN under `covisibility`)
  double ratio = 1;    ///< r = H / mean(FIFO) (1 while the FIFO is empty)
};

class KeyframePolicy {
 public:
  explicit KeyframePolicy(const KeyframePolicyParams& params = KeyframePolicyParams());

  /// Decides for one frame (8-bit grey). Call once per tracked frame, in order.
  KeyframeDecision decide(const cv::Mat& grey, const TrackingState& state);
  /// Same with the frame's CLAHE entropy already measured.
  KeyframeDecision decideWithEntropy(double entropy, const TrackingState& state);
  /// CLAHE-equalised entropy of a frame, as used by decide() (BGR is converted;
  /// NaN for an empty or non-8-bit image, which never triggers the entropy rule).
  double claheEntropy(const cv::Mat& grey) const;
  /// Forget the history (new map / session).
  void reset();

  const KeyframePolicyParams& params() const { return params_; }

 private:
  KeyframePolicyParams params_;
  cv::Ptr<cv::CLAHE> clahe_;
  std::deque<double> fifo_;
  int frames_since_keyframe_ = 0;
};

}  // namespace hermes
