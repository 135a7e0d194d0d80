#include "hermes/agent/keyframe_policy.h"

#include <array>
#include <cmath>
#include <cstdint>
#include <limits>
#include <numeric>

namespace hermes {

Status KeyframePolicyParams::read(const Config& c, const std::string& p) {
  Status s = c.getChoice(p + ".policy", {"entropy", "covisibility"}, &policy);
  if (!s) return s;
  for (auto [key, ptr] : {std::pair<const char*, double*>{"clahe_clip", &clahe_clip},
                          {"ratio_low", &ratio_low},
                          {"ratio_high", &ratio_high},
                          {"min_tracked_ratio", &min_tracked_ratio}}) {
    s = c.get(p + "." + key, ptr);
    if (!s) return s;
  }
  for (auto [key, ptr] : {std::pair<const char*, int*>{"clahe_tiles", &clahe_tiles},
                          {"entropy_window", &entropy_window},
                          {"max_frames", &max_frames},
                          {"min_frames", &min_frames},
                          {"min_tracked", &min_tracked},
                          {"few_tracked", &few_tracked}}) {
    s = c.get(p + "." + key, ptr);
    if (!s) return s;
  }
  return validate();
}

void KeyframePolicyParams::write(ConfigWriter* w, const std::string& p) const {
  w->set(p + ".policy", policy);
  w->set(p + ".clahe_clip", clahe_clip);
  w->set(p + ".clahe_tiles", clahe_tiles);
  w->set(p + ".entropy_window", entropy_window);
  w->set(p + ".ratio_low", ratio_low);
  w->set(p + ".ratio_high", ratio_high);
  w->set(p + ".min_tracked_ratio", min_tracked_ratio);
  w->set(p + ".max_frames", max_frames);
  w->set(p + ".min_frames", min_frames);
  w->set(p + ".min_tracked", min_tracked);
  w->set(p + ".few_tracked", few_tracked);
}

Status KeyframePolicyParams::validate() const {
  if (policy != "entropy" && policy != "covisibility")
    return Error{"keyframe.policy must be entropy or covisibility, got '" + policy + "'"};
  if (!(clahe_clip > 0)) return Error{"keyframe.clahe_clip must be > 0"};
  if (clahe_tiles < 1 || clahe_tiles > 64) return Error{"keyframe.clahe_tiles must be in [1, 64]"};
  if (entropy_window < 1) return Error{"keyframe.entropy_window must be >= 1"};
  if (!(ratio_low > 0 && ratio_low <= 1 && ratio_high >= 1))
    return Error{"keyframe.ratio_low/ratio_high must satisfy 0 < t_l <= 1 <= t_h"};
  if (!(min_tracked_ratio >= 0 && min_tracked_ratio <= 1))
    return Error{"keyframe.min_tracked_ratio must be in [0, 1]"};
  if (max_frames < 1) return Error{"keyframe.max_frames must be >= 1"};
  if (min_frames < 0 || min_frames > max_frames)
    return Error{"keyframe.min_frames must be in [0, max_frames]"};
  if (min_tracked < 0) return Error{"keyframe.min_tracked must be >= 0"};
  if (few_tracked < 0) return Error{"keyframe.few_tracked must be >= 0 (0 = off)"};
  return Status::Ok();
}

double imageEntropy(const cv::Mat& grey) {
  if (grey.type() != CV_8UC1 || grey.empty()) return std::numeric_limits<double>::quiet_NaN();
  std::array<std::uint64_t, 256> hist{};
  for (int y = 0; y < grey.rows; ++y) {
    const uchar* r = grey.ptr<uchar>(y);
    for (int x = 0; x < grey.cols; ++x) ++hist[r[x]];
  }
  const double n = double(grey.total());
  double h = 0.0;
  for (auto c : hist) {
    if (c == 0) continue;
    const double p = double(c) / n;
    h -= p * std::log2(p);
  }
  return h;
}

KeyframePolicy::KeyframePolicy(const KeyframePolicyParams& params) : params_(params) {
  Status s = params_.validate();
  HERMES_CHECK(s.ok(), s.error());
  clahe_ = cv::createCLAHE(params_.clahe_clip, cv::Size(params_.clahe_tiles, params_.clahe_tiles));
}

double KeyframePolicy::claheEntropy(const cv::Mat& grey) const {
  // Bad frames give NaN: the entropy rule then stays silent for that frame.
  if (grey.empty()) return std::numeric_limits<double>::quiet_NaN();
  cv::Mat g = grey;
  if (grey.type() == CV_8UC3) cv::cvtColor(grey, g, cv::COLOR_BGR2GRAY);
  if (g.type() != CV_8UC1) return std::numeric_limits<double>::quiet_NaN();
  cv::Mat eq;
  clahe_->apply(g, eq);
  return imageEntropy(eq);
}

void KeyframePolicy::reset() {
  fifo_.clear();
  frames_since_keyframe_ = 0;
}

KeyframeDecision KeyframePolicy::decide(const cv::Mat& grey, const TrackingState& state) {
  const double h = params_.policy == "entropy" ? claheEntropy(grey)
                                              : std::numeric_limits<double>::quiet_NaN();
  return decideWithEntropy(h, state);
}

KeyframeDecision KeyframePolicy::decideWithEntropy(double entropy, const TrackingState& state) {
  KeyframeDecision d;
  d.entropy = entropy;
  ++frames_since_keyframe_;
  if (params_.policy == "entropy" && std::isfinite(entropy)) {
    if (!fifo_.empty()) {
      const double mean = std::accumulate(fifo_.begin(), fifo_.end(), 0.0) / fifo_.size();
      d.ratio = mean > 0 ? entropy / mean : 1.0;
      d.by_entropy = d.ratio < params_.ratio_low || d.ratio > params_.ratio_high;
    }
    fifo_.push_back(entropy);
    while (int(fifo_.size()) > params_.entropy_window) fifo_.pop_front();
  }
  const bool healthy = state.ok && state.tracked >= params_.min_tracked;
  if (!healthy) return d;  // no keyframe from a frame whose pose is doubtful
  if (state.reference_tracked > 0)
    d.by_tracked_ratio =
        double(state.tracked) < params_.min_tracked_ratio * double(state.reference_tracked);
  d.by_max_frames = frames_since_keyframe_ >= params_.max_frames;
  d.by_few_tracked = state.tracked < params_.few_tracked;
  d.insert = frames_since_keyframe_ >= params_.min_frames &&
             (d.by_entropy || d.by_tracked_ratio || d.by_max_frames || d.by_few_tracked);
  if (d.insert) frames_since_keyframe_ = 0;
  return d;
}

}  // namespace hermes
