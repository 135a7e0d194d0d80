#include "hermes/core/dataset.h"

#include <cstdio>
#include <filesystem>

namespace fs = std::filesystem;

namespace hermes {

Status DatasetParams::read(const Config& cfg) {
  for (auto [key, out] : {std::pair<const char*, double*>{"dataset.tum_max_dt", &tum_max_dt},
                          {"dataset.tum_depth_scale", &tum_depth_scale},
                          {"dataset.rectify_alpha", &rectify_alpha}}) {
    Status s = cfg.get(key, out);
    if (!s) return s;
  }
  Status s = cfg.get("dataset.rectify", &rectify);
  if (!s) return s;
  return validate();
}

void DatasetParams::write(ConfigWriter& w) const {
  w.set("dataset.tum_max_dt", tum_max_dt);
  w.set("dataset.tum_depth_scale", tum_depth_scale);
  w.set("dataset.rectify", rectify);
  w.set("dataset.rectify_alpha", rectify_alpha);
}

Status DatasetParams::validate() const {
  if (!(tum_max_dt > 0 && tum_max_dt < 1.0))
    return Error{"dataset.tum_max_dt must lie in (0, 1) s, got " + std::to_string(tum_max_dt)};
  if (!(tum_depth_scale >= 0))
    return Error{"dataset.tum_depth_scale must be >= 0 (0 = from camera.yaml)"};
  if (!(rectify_alpha >= 0 && rectify_alpha <= 1))
    return Error{"dataset.rectify_alpha must lie in [0, 1]"};
  return Status::Ok();
}

const char* toString(DatasetKind k) {
  switch (k) {
    case DatasetKind::kEuroc: return "euroc";
    case DatasetKind::kTum: return "tum";
    case DatasetKind::kKitti: return "kitti";
  }
  return "?";
}

std::string DatasetInfo::summary() const {
  char buf[256];
  std::snprintf(buf, sizeof(buf),
                "%s dataset '%s': %zu frames, %.2f s, %dx%d fx %.2f%s, ground truth: %zu poses",
                layout.c_str(), root.c_str(), frame_count, t_end - t_start, K.width, K.height,
                K.fx,
                baseline > 0 ? (", baseline " + std::to_string(baseline) + " m").c_str() : "",
                groundtruth.size());
  return buf;
}

Expected<DatasetKind> detectDatasetKind(const std::string& dir) {
  std::error_code ec;
  const fs::path d(dir);
  if (!fs::is_directory(d, ec)) return Error{"dataset folder '" + dir + "' does not exist"};
  if (fs::exists(d / "mav0" / "cam0" / "data.csv", ec) || fs::exists(d / "cam0" / "data.csv", ec))
    return DatasetKind::kEuroc;
  if (fs::exists(d / "rgb.txt", ec) && fs::exists(d / "depth.txt", ec)) return DatasetKind::kTum;
  if (fs::exists(d / "associations.txt", ec)) return DatasetKind::kTum;  // ICL-NUIM
  if (looksLikeKittiSequence(dir)) return DatasetKind::kKitti;
  std::string hint;
  if (fs::is_directory(d / "sequences", ec))
    hint = " (a KITTI odometry root: give one sequence, e.g. '" + (d / "sequences" / "00").string() + "')";
  return Error{"'" + dir + "' is not a dataset folder Hermes reads" + hint +
               "; looked for: EuRoC (mav0/cam0/data.csv or cam0/data.csv), TUM RGB-D (rgb.txt + "
               "depth.txt), ICL-NUIM (associations.txt), KITTI odometry (image_0/, image_1/, "
               "calib.txt)"};
}

Expected<std::unique_ptr<Dataset>> Dataset::open(const std::string& dir,
                                                 const DatasetParams& params) {
  if (Status s = params.validate(); !s) return Error{s.error()};
  auto kind = detectDatasetKind(dir);
  if (!kind) return Error{kind.error()};
  std::unique_ptr<Dataset> ds(new Dataset());
  DatasetInfo& info = ds->info_;
  info.kind = *kind;
  info.root = dir;
  if (*kind == DatasetKind::kKitti) {
    auto k = KittiDataset::open(dir);
    if (!k) return Error{k.error()};
    info.layout = "kitti";
    info.frame_count = k->size();
    const KittiCalibration& c = k->calibration();
    PinholeRadtan left;
    left.K = c.K;
    left.dist.fill(0.0);
    left.rate_hz = 10.0;
    PinholeRadtan right = left;
    right.T_B_C = SE3(Mat3::Identity(), Vec3(c.baseline, 0, 0));
    info.stereo = StereoRig{left, right};
    info.K = c.K;
    info.baseline = c.baseline;
    info.groundtruth = k->groundTruth();
    info.t_start = k->pairs().front().t;
    info.t_end = k->pairs().back().t;
    info.warnings = k->warnings();
    ds->data_ = std::move(*k);
  } else if (*kind == DatasetKind::kEuroc) {
    info.layout = "euroc";
    auto e = EurocDataset::open(dir);
    if (!e) return Error{e.error()};
    info.frame_count = e->size();
    info.stereo = StereoRig{e->cam0(), e->cam1()};
    info.groundtruth = e->groundTruth();
    info.t_start = nsToSeconds(e->pairs().front().stamp_ns);
    info.t_end = nsToSeconds(e->pairs().back().stamp_ns);
    const auto& sk = e->skipped();
    if (sk.cam0_missing_image + sk.cam1_missing_image + sk.cam0_unpaired + sk.cam1_unpaired > 0)
      info.warnings.push_back(
          "skipped csv rows: cam0 " + std::to_string(sk.cam0_missing_image) + " without image, " +
          std::to_string(sk.cam0_unpaired) + " unpaired; cam1 " +
          std::to_string(sk.cam1_missing_image) + " without image, " +
          std::to_string(sk.cam1_unpaired) + " unpaired");
    if (params.rectify) {
      RectifyOptions ro;
      ro.alpha = params.rectify_alpha;
      auto r = rectify(*info.stereo, ro);
      if (!r) return Error{dir + ": " + r.error()};
      info.K = r->K;
      info.baseline = r->baseline;
      info.T_B_C = r->T_B_Crect;
      ds->rectified_ = std::move(*r);
    } else {
      info.K = e->cam0().K;
      info.baseline = info.stereo->T_Cl_Cr().translation().norm();
      info.T_B_C = e->cam0().T_B_C;
    }
    ds->data_ = std::move(*e);
  } else {
    TumOptions to;
    to.max_dt = params.tum_max_dt;
    to.depth_scale = params.tum_depth_scale;
    auto t = TumDataset::open(dir, to);
    if (!t) return Error{t.error()};
    info.layout = t->iclNuimLayout() ? "icl_nuim" : "tum";
    info.frame_count = t->size();
    info.rgbd = t->camera();
    info.K = t->camera().K;
    info.T_B_C = t->camera().T_B_C;
    info.groundtruth = t->groundTruth();
    info.t_start = t->pairs().front().t_rgb;
    info.t_end = t->pairs().back().t_rgb;
    info.warnings = t->warnings();
    const auto& sk = t->skipped();
    if (sk.rgb_missing_image + sk.depth_missing_image + sk.rgb_unmatched + sk.depth_unmatched > 0)
      info.warnings.push_back(
          "skipped list rows: rgb " + std::to_string(sk.rgb_missing_image) + " without image, " +
          std::to_string(sk.rgb_unmatched) + " unmatched; depth " +
          std::to_string(sk.depth_missing_image) + " without image, " +
          std::to_string(sk.depth_unmatched) + " unmatched");
    ds->data_ = std::move(*t);
  }
  return ds;
}

double Dataset::frameTime(std::size_t i) const {
  HERMES_CHECK(i < size(), "frameTime index out of range");
  if (const auto* e = euroc()) return nsToSeconds(e->pairs()[i].stamp_ns);
  if (const auto* k = kitti()) return k->pairs()[i].t;
  return tum()->pairs()[i].t_rgb;
}

Expected<StereoFrame> Dataset::loadStereo(std::size_t i) const {
  if (const auto* k = kitti()) return k->load(i);
  const auto* e = euroc();
  if (!e) return Error{"'" + info_.root + "' is a TUM RGB-D dataset, not stereo"};
  auto f = e->load(i);
  if (!f || !rectified_) return f;
  cv::Mat l, r;
  rectified_->rectifyImages(f->left, f->right, &l, &r);
  f->left = l;
  f->right = r;
  f->rectified = true;
  return f;
}

Expected<RgbdFrame> Dataset::loadRgbd(std::size_t i) const {
  const auto* t = tum();
  if (!t) return Error{"'" + info_.root + "' is a stereo dataset, not RGB-D"};
  return t->load(i);
}

Expected<DatasetInfo> probeDataset(const std::string& dir, const DatasetParams& params) {
  auto ds = Dataset::open(dir, params);
  if (!ds) return Error{ds.error()};
  return (*ds)->info();
}

}  // namespace hermes
