#include "hermes/agent/dataset_feed.h"

namespace hermes {

Expected<CameraFrame> loadCameraFrame(const Dataset& dataset, std::size_t i) {
  CameraFrame frame;
  if (isStereo(dataset.info().kind)) {
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

CameraCalibration datasetCalibration(const Dataset& dataset) {
  const DatasetInfo& info = dataset.info();
  CameraCalibration c;
  c.format = "dataset";
  c.source = info.root;
  c.width = info.K.width;
  c.height = info.K.height;
  if (info.kind == DatasetKind::kTum) {
    c.kind = CameraCalibration::Kind::kRgbd;
    c.rgbd = *info.rgbd;
    c.rgbd.T_B_C = info.T_B_C;
  } else if (!dataset.stereoRectified()) {
    c.stereo = *info.stereo;
  } else {
    PinholeRadtan left;
    left.K = info.K;
    left.dist.fill(0.0);
    left.T_B_C = info.T_B_C;
    left.rate_hz = info.stereo->left.rate_hz;
    PinholeRadtan right = left;
    right.T_B_C = info.T_B_C * SE3(Mat3::Identity(), Vec3(info.baseline, 0, 0));
    c.stereo = StereoRig{left, right};
    c.rectified = true;
  }
  return c;
}

}  // namespace hermes
