#include "hermes/agent/camera_stream.h"

#include <cstdio>
#include <utility>

namespace hermes::agent {
Expected<CameraStream> CameraStream::create(const CameraCalibration& calibration,
                                            const CameraInputParams& params,
                                            const std::string& name_a,
                                            const std::string& name_b) {
  auto input = CameraInput::create(calibration, params);
  if (!input.ok()) return Error{input.error()};
  return CameraStream(std::move(*input), name_a, name_b);
}

CameraStream::CameraStream(CameraInput input, const std::string& name_a,
                           const std::string& name_b)
    : input_(std::move(input)), sync_(input_.syncParams()), name_a_(name_a), name_b_(name_b) {}

void CameraStream::pushA(InputImage image) {
  const double t = image.stamp;
  sync_.push_a(t, std::move(image));
  checkPairing();
}

void CameraStream::pushB(InputImage image) {
  const double t = image.stamp;
  sync_.push_b(t, std::move(image));
  checkPairing();
}

void CameraStream::checkPairing() {
  if (never_paired_reported_ || !sync_.neverPaired()) return;
  never_paired_reported_ = true;
  const SyncStats& s = sync_.stats();
  char slop[32];
  std::snprintf(slop, sizeof slop, "%.3f", input_.syncParams().slop);
  problems_.push_back(
      std::string(isStereo() ? "stereo" : "RGB-D") + " stamps never pair: " +
      std::to_string(s.received_a) + " images on " + name_a_ + " (newest " +
      stampText(s.newest_a) + " s) and " + std::to_string(s.received_b) + " on " + name_b_ +
      " (newest " + stampText(s.newest_b) + " s), not one pair within " + slop +
      " s (camera_input." + (isStereo() ? "stereo_slop" : "rgbd_slop") +
      "); are the topics from the same camera and its clock?");
}

void CameraStream::note(const std::string& cause, const std::string& message) {
  ++rejected_;
  if (++own_causes_[cause] == 1) problems_.push_back(cause + ": " + message);
}

std::optional<CameraFrame> CameraStream::next() {
  while (auto pair = sync_.pop()) {
    InputImage& a = pair->a;
    InputImage& b = pair->b;
    if (isStereo() && a.encoding != b.encoding) {
      note("encodings differ", "stereo frame " + stampText(a.stamp) + ": " + name_a_ + " is '" +
                                   a.encoding + "' but " + name_b_ + " is '" + b.encoding + "'");
      continue;
    }
    auto f = isStereo() ? input_.stereo(a.stamp, a.image, b.image, a.encoding)
                        : input_.rgbd(a.stamp, a.image, a.encoding, b.image, b.encoding);
    if (f.ok()) {
      // The frame outlives the pair: pixels it shares with an input that only
      // views a buffer (e.g. a message's, released with `owner`) are copied.
      for (cv::Mat* m : {&f->left, &f->right, &f->depth})
        if (!m->empty() && m->u == nullptr) *m = m->clone();
      return std::move(*f);
    }
    ++rejected_;
    if (input_.lastErrorIsNew()) problems_.push_back(input_.lastErrorCause() + ": " + f.error());
  }
  return std::nullopt;
}

std::vector<std::string> CameraStream::problems() {
  std::vector<std::string> out;
  out.swap(problems_);
  return out;
}

StreamCounters CameraStream::counters() const {
  const SyncStats& s = sync_.stats();
  StreamCounters c;
  c.received_a = s.received_a;
  c.received_b = s.received_b;
  c.paired = s.paired;
  c.unpaired_a = s.dropped_a;
  c.unpaired_b = s.dropped_b;
  c.out_of_order = s.out_of_order;
  c.converted = input_.framesConverted();
  c.rejected = rejected_;
  c.rejected_by_cause = input_.errorCounts();
  for (const auto& [cause, n] : own_causes_) c.rejected_by_cause[cause] += n;
  return c;
}

}  // namespace hermes::agent
