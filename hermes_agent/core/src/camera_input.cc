#include "hermes/agent/camera_input.h"

#include <cmath>
#include <cstdio>
#include <sstream>
#include <utility>

#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>

#include "hermes/agent/rgbd_depth.h"

namespace hermes::agent {
namespace {

std::string sizeText(int w, int h) { return std::to_string(w) + "x" + std::to_string(h); }

// Channels an 8-bit encoding needs and its conversion to grey (-1: none); 0 channels = unknown.
std::pair<int, int> greyConversion(const std::string& enc) {
  if (enc == "mono8" || enc == "8UC1") return {1, -1};
  if (enc == "bgr8") return {3, cv::COLOR_BGR2GRAY};
  if (enc == "rgb8") return {3, cv::COLOR_RGB2GRAY};
  if (enc == "bgra8") return {4, cv::COLOR_BGRA2GRAY};
  if (enc == "rgba8") return {4, cv::COLOR_RGBA2GRAY};
  return {0, -1};
}

}  // namespace

std::string stampText(double t_s) {
  char buf[48];
  std::snprintf(buf, sizeof buf, "%.6f", t_s);
  return buf;
}

Status CameraInputParams::read(const Config& c, const std::string& p) {
  Status s = c.getChoice(p + ".stereo_images", {"auto", "raw", "rectified"}, &stereo_images);
  if (!s) return s;
  for (auto [key, ptr] : {std::pair<const char*, double*>{"rectify_alpha", &rectify_alpha},
                          {"depth_scale_16u", &depth_scale_16u},
                          {"stereo_slop", &stereo_slop},
                          {"rgbd_slop", &rgbd_slop}}) {
    s = c.get(p + "." + key, ptr);
    if (!s) return s;
  }
  s = c.get(p + ".sync_capacity", &sync_capacity);
  if (!s) return s;
  return validate();
}

void CameraInputParams::write(ConfigWriter* w, const std::string& p) const {
  w->set(p + ".stereo_images", stereo_images);
  w->set(p + ".rectify_alpha", rectify_alpha);
  w->set(p + ".depth_scale_16u", depth_scale_16u);
  w->set(p + ".stereo_slop", stereo_slop);
  w->set(p + ".rgbd_slop", rgbd_slop);
  w->set(p + ".sync_capacity", sync_capacity);
}

Status CameraInputParams::validate() const {
  if (stereo_images != "auto" && stereo_images != "raw" && stereo_images != "rectified")
    return Error{"camera_input.stereo_images must be auto, raw or rectified, got '" +
                 stereo_images + "'"};
  if (!(rectify_alpha >= 0 && rectify_alpha <= 1))
    return Error{"camera_input.rectify_alpha must be in [0, 1]"};
  if (!(depth_scale_16u >= 0 && std::isfinite(depth_scale_16u)))
    return Error{"camera_input.depth_scale_16u must be >= 0 (0 = the calibration's)"};
  if (!(stereo_slop >= 0 && stereo_slop < 1 && rgbd_slop >= 0 && rgbd_slop < 1))
    return Error{"camera_input.stereo_slop and rgbd_slop must be in [0, 1) [s]"};
  if (sync_capacity < 1 || sync_capacity > 1000)
    return Error{"camera_input.sync_capacity must be in [1, 1000]"};
  return Status::Ok();
}

Expected<CameraInput> CameraInput::create(const CameraCalibration& calib,
                                          const CameraInputParams& params) {
  if (Status s = params.validate(); !s) return Error{s.error()};
  if (Status s = calib.validate(); !s) return Error{s.error()};
  CameraInput in;
  in.calib_ = calib;
  in.params_ = params;
  in.depth_scale_16u_ = params.depth_scale_16u > 0 ? params.depth_scale_16u
                                                     : calib.rgbd.depth_scale;
  const cv::Size size(calib.width, calib.height);
  if (calib.kind == CameraCalibration::Kind::kRgbd) {
    in.camera_ = AgentCamera{calib.rgbd.K, 0.0, calib.rgbd.T_B_C};
    in.undistort_ = calib.rgbd.hasDistortion();
    if (in.undistort_) {  // into the colour K itself
      const PinholeIntrinsics& K = calib.rgbd.K;
      const cv::Mat Kcv = (cv::Mat_<double>(3, 3) << K.fx, 0, K.cx, 0, K.fy, K.cy, 0, 0, 1);
      cv::Mat dist(1, 5, CV_64F);
      for (int i = 0; i < 5; ++i) dist.at<double>(0, i) = calib.rgbd.dist[i];
      cv::initUndistortRectifyMap(Kcv, dist, cv::noArray(), Kcv, size, CV_32FC1, in.map_x_,
                                  in.map_y_);
    }
  } else {
    const bool raw = params.stereo_images == "raw" ||
                     (params.stereo_images == "auto" && !calib.rectified);
    if (raw) {
      if (calib.rectified && !calib.raw_stereo)
        return Error{calib.source + ": camera_input.stereo_images is 'raw' but the calibration "
                     "is rectified and holds no raw cameras"};
      RectifyOptions opt;
      opt.alpha = params.rectify_alpha;
      auto rect = rectify(calib.rectified ? *calib.raw_stereo : calib.stereo, opt);
      if (!rect.ok()) return Error{calib.source + ": " + rect.error()};
      in.rect_ = std::move(*rect);
      in.rectify_ = true;
      in.camera_ = AgentCamera{in.rect_.K, in.rect_.baseline, in.rect_.T_B_Crect};
    } else {
      if (!calib.rectified)
        return Error{calib.source + ": camera_input.stereo_images is 'rectified' but the "
                     "calibration describes raw (distorted) cameras"};
      in.camera_ = AgentCamera{calib.stereo.left.K, calib.stereo.T_Cl_Cr().translation().x(),
                               calib.stereo.left.T_B_C};
      in.right_shift_px_ = calib.stereo.left.K.cx - calib.stereo.right.K.cx;
    }
  }
  in.camera_.K.width = calib.width;
  in.camera_.K.height = calib.height;
  return in;
}

SyncParams CameraInput::syncParams() const {
  SyncParams s;
  s.slop = isStereo() ? params_.stereo_slop : params_.rgbd_slop;
  s.capacity = params_.sync_capacity;
  return s;
}

std::string CameraInput::summary() const {
  std::ostringstream o;
  o.precision(6);
  if (!isStereo())
    o << "rgbd, " << (undistort_ ? "colour undistorted into its K" : "images as published")
      << ", 16UC1 depth / " << depth_scale_16u_ << " = metres";
  else
    o << "stereo, " << (rectify_ ? "rectified here" : "images rectified by the source")
      << (right_shift_px_ != 0 ? ", right image shifted by " + std::to_string(right_shift_px_) +
                                     " px"
                               : std::string())
      << ", baseline " << camera_.baseline << " m";
  o << ", K fx " << camera_.K.fx << " fy " << camera_.K.fy << " cx " << camera_.K.cx << " cy "
    << camera_.K.cy << " " << sizeText(camera_.K.width, camera_.K.height) << " ("
    << calib_.source << ")";
  return o.str();
}

bool CameraInput::lastErrorIsNew() const {
  auto it = errors_.find(last_cause_);
  return it != errors_.end() && it->second == 1;
}

Error CameraInput::fail(const std::string& cause, const std::string& message) {
  ++errors_[cause];
  last_cause_ = cause;
  return Error{message};
}

Expected<cv::Mat> CameraInput::grey(const cv::Mat& image, const std::string& enc,
                                    const std::string& what) {
  if (image.empty()) return fail("empty image", "the " + what + " image is empty");
  const auto [channels, code] = greyConversion(enc);
  if (channels == 0)
    return fail("unsupported encoding", "unsupported encoding '" + enc + "' on the " + what +
                                            " image (use mono8, bgr8, rgb8, bgra8 or rgba8)");
  if (image.type() != CV_8UC(channels))
    return fail("type does not match encoding",
                "the " + what + " image has " + std::to_string(image.channels()) +
                    " channel(s) of depth " + std::to_string(image.depth()) + " but encoding '" +
                    enc + "' needs " + std::to_string(channels) + " 8-bit channel(s)");
  if (image.cols != calib_.width || image.rows != calib_.height)
    return fail("size mismatch", "the " + what + " image is " +
                                     sizeText(image.cols, image.rows) +
                                     " but the calibration says " +
                                     sizeText(calib_.width, calib_.height));
  if (code < 0) return image;
  cv::Mat g;
  cv::cvtColor(image, g, code);
  return g;
}

Expected<CameraFrame> CameraInput::stereo(double stamp, const cv::Mat& left,
                                          const cv::Mat& right, const std::string& encoding) {
  const std::string at = "stereo frame " + stampText(stamp) + ": ";
  if (!isStereo())
    return fail("wrong camera kind", at + "stereo images given to the RGB-D camera of " +
                                         calib_.source);
  if (!std::isfinite(stamp)) return fail("bad stamp", at + "the stamp is not finite");
  auto l = grey(left, encoding, "left");
  if (!l.ok()) return Error{at + l.error()};
  auto r = grey(right, encoding, "right");
  if (!r.ok()) return Error{at + r.error()};
  CameraFrame f;
  f.stamp = stamp;
  if (rectify_) {
    rect_.rectifyImages(*l, *r, &f.left, &f.right);
  } else {
    f.left = *l;
    f.right = *r;
    if (right_shift_px_ != 0) {  // right(u) -> right(u + cx_l - cx_r)
      const cv::Mat M = (cv::Mat_<double>(2, 3) << 1, 0, right_shift_px_, 0, 1, 0);
      cv::warpAffine(*r, f.right, M, r->size(), cv::INTER_LINEAR, cv::BORDER_CONSTANT);
    }
  }
  ++converted_;
  return f;
}

Expected<CameraFrame> CameraInput::rgbd(double stamp, const cv::Mat& colour,
                                        const std::string& colour_encoding,
                                        const cv::Mat& depth, const std::string& depth_encoding) {
  const std::string at = "RGB-D frame " + stampText(stamp) + ": ";
  if (isStereo())
    return fail("wrong camera kind", at + "RGB-D images given to the stereo camera of " +
                                         calib_.source);
  if (!std::isfinite(stamp)) return fail("bad stamp", at + "the stamp is not finite");
  auto g = grey(colour, colour_encoding, "colour");
  if (!g.ok()) return Error{at + g.error()};
  if (depth.empty()) return fail("empty image", at + "the depth image is empty");
  const bool u16 = depth_encoding == "16UC1" || depth_encoding == "mono16";
  if (!u16 && depth_encoding != "32FC1")
    return fail("unsupported encoding", at + "unsupported encoding '" + depth_encoding +
                                            "' on the depth image (use 16UC1, mono16 or 32FC1)");
  if (depth.type() != (u16 ? CV_16UC1 : CV_32FC1))
    return fail("type does not match encoding",
                at + "the depth image has " + std::to_string(depth.channels()) +
                    " channel(s) of depth " + std::to_string(depth.depth()) + " but encoding '" +
                    depth_encoding + "' needs one " + (u16 ? "16-bit" : "float") + " channel");
  if (depth.cols != calib_.width || depth.rows != calib_.height)
    return fail("size mismatch", at + "the depth image is " + sizeText(depth.cols, depth.rows) +
                                     " but the calibration says " +
                                     sizeText(calib_.width, calib_.height));
  auto metres = depthToMetres(depth, u16 ? depth_scale_16u_ : 1.0);  // invalid -> 0
  HERMES_CHECK(metres.ok(), metres.error());  // type and scale were checked above
  CameraFrame f;
  f.stamp = stamp;
  if (undistort_) {
    cv::remap(*g, f.left, map_x_, map_y_, cv::INTER_LINEAR, cv::BORDER_CONSTANT, cv::Scalar(0));
    cv::remap(*metres, f.depth, map_x_, map_y_, cv::INTER_NEAREST, cv::BORDER_CONSTANT,
              cv::Scalar(0));
  } else {
    f.left = *g;
    f.depth = std::move(*metres);
  }
  ++converted_;
  return f;
}

}  // namespace hermes::agent
