#include "hermes/agent/dataset_feed.h"

namespace hermes {

Expected<CameraFrame> loadCameraFrame(const Dataset& dataset, std::size_t i) {
  CameraFrame frame;
  if (dataset.info().kind == DatasetKind::kEuroc) {
    auto f = dataset.loadStereo(i);
    if (!f.ok()) return Error{f.error()};
    frame.stamp = f->t;
    frame.left = f->left;
    frame.right = f->right;
  } else {
    auto f = dataset.loadRgbd(i);
    if (!f.ok()) return Error{f.error()};
    frame.stamp = f->t;
    frame.left = f->gray;
    frame.depth = f->depth_m;
  }
  return frame;
}

}  // namespace hermes
