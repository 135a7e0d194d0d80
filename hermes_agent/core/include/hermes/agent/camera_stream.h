// Two image topics of one robot -> CameraFrames in stamp order, ROS-free.
// A CameraStream pairs stream A (left / colour) with stream B (right / depth)
// by stamp (ApproximateSync, camera_input.stereo_slop or rgbd_slop) and
// converts each pair with a CameraInput (rectification, undistortion, depth
// units). It counts what happened to every image and turns each new kind of
// problem into one log line (problems()), so a node logs a cause once instead
// of once per frame:
//   * a pair the CameraInput rejects (per cause: "unsupported encoding", ...);
//   * left and right images in different encodings ("encodings differ");
//   * stamps that never pair (both streams sent SyncParams::never_paired_after
//     images and not one pair was made): the message names both streams, their
//     newest stamps and the slop.
// Not thread-safe: callers lock.
#pragma once

#include <cstdint>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "hermes/agent/approximate_sync.h"
#include "hermes/agent/camera_input.h"

namespace hermes::agent {

/// One image as it came from a topic: stamp, encoding name (ROS
/// sensor_msgs/image_encodings) and pixels. `image` may be a view of a
/// message's buffer: `owner` keeps that buffer alive.
struct InputImage {
  double stamp = 0;  ///< [s]
  std::string encoding;
  cv::Mat image;
  std::shared_ptr<const void> owner;
};

/// What happened to the images of one stream set, for status reports.
struct StreamCounters {
  std::int64_t received_a = 0, received_b = 0;  ///< images pushed
  std::int64_t paired = 0;                      ///< pairs made by the sync
  std::int64_t unpaired_a = 0, unpaired_b = 0;  ///< images dropped without a partner
  std::int64_t out_of_order = 0;                ///< images older than their stream's newest
  std::int64_t converted = 0;                   ///< pairs handed out by next()
  std::int64_t rejected = 0;                    ///< pairs the conversion refused
  std::map<std::string, std::int64_t> rejected_by_cause;
};

class CameraStream {
 public:
  /// `name_a` / `name_b` name the streams in messages (e.g. the topics).
  /// Errors: as CameraInput::create.
  static Expected<CameraStream> create(const CameraCalibration& calibration,
                                       const CameraInputParams& params,
                                       const std::string& name_a, const std::string& name_b);

  const CameraInput& input() const { return input_; }
  /// The camera the pipeline must be created with.
  const AgentCamera& camera() const { return input_.camera(); }
  bool isStereo() const { return input_.isStereo(); }

  void pushA(InputImage image);  ///< left (stereo) / colour (RGB-D)
  void pushB(InputImage image);  ///< right (stereo) / depth (RGB-D)

  /// The next pair converted into a frame (stamp: A's), oldest first; pairs
  /// the conversion rejects are counted, noted in problems() and skipped.
  /// The frame owns its pixels (an input's view of an outside buffer, which
  /// InputImage::owner keeps only as long as the pair, is copied).
  /// nullopt when no pair is waiting.
  std::optional<CameraFrame> next();

  /// Problems not reported yet, one line each (see the header comment); the
  /// list is emptied by the call.
  std::vector<std::string> problems();

  StreamCounters counters() const;
  const SyncStats& syncStats() const { return sync_.stats(); }

 private:
  CameraStream(CameraInput input, const std::string& name_a, const std::string& name_b);
  void note(const std::string& cause, const std::string& message);
  void checkPairing();

  CameraInput input_;
  ApproximateSync<InputImage, InputImage> sync_;
  std::string name_a_, name_b_;
  std::int64_t rejected_ = 0;
  std::map<std::string, std::int64_t> own_causes_;  ///< causes found here, not in input_
  std::vector<std::string> problems_;
  bool never_paired_reported_ = false;
};

}  // namespace hermes::agent
