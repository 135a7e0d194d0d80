// A rendered stereo / RGB-D sequence through the room-corner scene with known
// ground truth, fed to a Tracker frame by frame (shared by mapping tests).
#pragma once

#include <functional>

#include <opencv2/core.hpp>

#include "hermes/agent/tracker.h"

namespace hermes::test {

PinholeIntrinsics roomK();

/// Ground-truth camera pose (W <- C) of frame k at 20 Hz.
SE3 roomGroundTruth(int k);

/// `img` plus Gaussian sensor noise (sigma 2 grey levels), seeded.
cv::Mat addSensorNoise(const cv::Mat& img, int seed);

struct RoomRunStats {
  int frames = 0, lost = 0, keyframes = 0;
  double rmse = 0;        ///< position RMSE in the first camera's frame [m]
  double max_ba_ms = 0, mean_ba_ms = 0;
};

/// Runs `frames` frames (stereo or RGB-D) through `tracker`; `after` is called
/// after every frame with its stamp and result. Empty stats if photos are missing.
RoomRunStats runRoomSequence(Tracker* tracker, bool stereo, int frames,
                             const std::function<void(double, const TrackResult&)>& after = {});

}  // namespace hermes::test
