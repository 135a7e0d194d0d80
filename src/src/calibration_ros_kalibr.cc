// Kalibr camchain.yaml and ROS camera_info YAML readers (declared in
// camera_calibration.h), written from the formats' documentation:
//   Kalibr:  camN: {camera_model, intrinsics [fu fv pu pv], distortion_model,
//            distortion_coeffs, resolution [w h], T_cn_cnm1 (camN <- camN-1),
//            T_cam_imu (cam <- imu), ...}
//   ROS:     image_width, image_height, camera_name, camera_matrix, distortion_model,
//            distortion_coefficients, rectification_matrix, projection_matrix
//            (matrices as {rows, cols, data}).
#include <algorithm>
#include <array>
#include <cmath>
#include <vector>

#include "calib_yaml.h"
#include "hermes/core/camera_calibration.h"

using namespace hermes::calib_yaml;  // NOLINT: private helpers

namespace hermes {
namespace {

Status readKalibrCamera(const YAML::Node& root, const std::string& key, const Where& w,
                        PinholeRadtan* cam) {
  auto m = subMap(root, key, w);
  if (!m) return Error{m.error()};
  const Where in = w.child(key);
  auto model = text(*m, "camera_model", in);
  if (!model) return Error{model.error()};
  if (*model != "pinhole")
    return in.bad(get(*m, "camera_model"), "camera_model",
                  "'" + *model + "' is not supported (pinhole only)");
  auto intr = numbers(*m, "intrinsics", in, {4});
  if (!intr) return Error{intr.error()};
  if (Status s = resolution(*m, "resolution", in, &cam->K.width, &cam->K.height); !s) return s;
  cam->K.fx = (*intr)[0];
  cam->K.fy = (*intr)[1];
  cam->K.cx = (*intr)[2];
  cam->K.cy = (*intr)[3];
  auto dmodel = text(*m, "distortion_model", in);
  if (!dmodel) return Error{dmodel.error()};
  auto coeffs = numbers(*m, "distortion_coeffs", in, {});
  if (!coeffs) return Error{coeffs.error()};
  if (*dmodel != "none" && *dmodel != "radtan" && *dmodel != "equidistant")
    return in.bad(get(*m, "distortion_model"), "distortion_model",
                  "'" + *dmodel + "' is not supported (radtan, equidistant, none)");
  cam->rate_hz = 0;  // Kalibr records no frame rate
  return setDistortion(*dmodel, *coeffs, *m, "distortion_model", "distortion_coeffs", in, cam);
}

Error pairError(const std::string& file, const std::string& what) {
  return Error{file + ": key 'projection_matrix' " + what};
}

}  // namespace

Expected<CameraCalibration> readKalibrCamchain(const std::string& path) {
  auto root = loadMap(path);
  if (!root) return Error{root.error()};
  const Where w{path, ""};
  CameraCalibration c;
  c.format = "kalibr";
  c.source = path;
  if (Status s = readKalibrCamera(*root, "cam0", w, &c.stereo.left); !s) return Error{s.error()};
  if (!get(*root, "cam1"))
    return Error{w.missing("cam1").message + " (Hermes needs a stereo pair)"};
  if (Status s = readKalibrCamera(*root, "cam1", w, &c.stereo.right); !s)
    return Error{s.error()};
  const YAML::Node cam0 = get(*root, "cam0"), cam1 = get(*root, "cam1");
  // Body: the IMU when cam0 knows its pose (T_cam_imu), else cam0 itself.
  if (get(cam0, "T_cam_imu")) {
    auto T = transform(cam0, "T_cam_imu", w.child("cam0"));
    if (!T) return Error{T.error()};
    c.stereo.left.T_B_C = T->inverse();
  }
  auto T_c1_c0 = transform(cam1, "T_cn_cnm1", w.child("cam1"));
  if (!T_c1_c0) return Error{T_c1_c0.error()};
  c.stereo.right.T_B_C = c.stereo.left.T_B_C * T_c1_c0->inverse();
  c.width = c.stereo.left.K.width;
  c.height = c.stereo.left.K.height;
  if (Status s = c.validate(); !s) return Error{s.error()};
  return c;
}

namespace {

/// One camera_info map (file or message); errors name w.file.
Expected<CameraInfo> parseCameraInfo(const YAML::Node* root, const Where& w) {
  CameraInfo ci;
  if (get(*root, "camera_name")) ci.camera_name = get(*root, "camera_name").Scalar();
  for (const auto& [key, out] :
       {std::pair{"image_width", &ci.width}, {"image_height", &ci.height}}) {
    auto v = number(*root, key, w);
    if (!v) return Error{v.error()};
    if (!(*v >= 1 && *v < 1e5 && *v == std::floor(*v)))
      return w.bad(get(*root, key), key, "must be a positive integer");
    *out = static_cast<int>(*v);
  }
  auto K = matrix(*root, "camera_matrix", w, 3, 3);
  if (!K) return Error{K.error()};
  for (int i = 0; i < 9; ++i) ci.K(i / 3, i % 3) = (*K)[i];
  if (ci.K(0, 1) != 0 || ci.K(1, 0) != 0 || ci.K(2, 0) != 0 || ci.K(2, 1) != 0 ||
      ci.K(2, 2) != 1 || !(ci.K(0, 0) > 0 && ci.K(1, 1) > 0))
    return w.bad(get(*root, "camera_matrix"), "camera_matrix",
                 "must be [fx 0 cx, 0 fy cy, 0 0 1] with fx, fy > 0");
  auto dmodel = text(*root, "distortion_model", w);
  if (!dmodel) return Error{dmodel.error()};
  ci.distortion_model = *dmodel;
  auto D = matrix(*root, "distortion_coefficients", w, 1, -1);
  if (!D) return Error{D.error()};
  ci.D = *D;
  auto R = matrix(*root, "rectification_matrix", w, 3, 3);
  if (!R) return Error{R.error()};
  auto Rm = rotation(*R, w.bad(get(*root, "rectification_matrix"), "rectification_matrix",
                               "is not a rotation"));
  if (!Rm) return Error{Rm.error()};
  ci.R = *Rm;
  auto P = matrix(*root, "projection_matrix", w, 3, 4);
  if (!P) return Error{P.error()};
  for (int i = 0; i < 12; ++i) ci.P(i / 4, i % 4) = (*P)[i];
  if (!(ci.P(0, 0) > 0 && ci.P(1, 1) > 0))
    return w.bad(get(*root, "projection_matrix"), "projection_matrix", "needs fx', fy' > 0");

  PinholeRadtan& cam = ci.camera;
  cam.K = PinholeIntrinsics{ci.K(0, 0), ci.K(1, 1), ci.K(0, 2), ci.K(1, 2), ci.width, ci.height};
  cam.rate_hz = 0;  // camera_info records no frame rate
  if (*dmodel != "plumb_bob" && *dmodel != "rational_polynomial" && *dmodel != "equidistant")
    return w.bad(get(*root, "distortion_model"), "distortion_model",
                 "'" + *dmodel + "' is not supported (plumb_bob, rational_polynomial, "
                 "equidistant)");
  std::vector<double> d = ci.D;
  // Some drivers pad plumb_bob to 8 values; the padding must be zero.
  if (*dmodel == "plumb_bob" && d.size() == 8 && d[5] == 0 && d[6] == 0 && d[7] == 0)
    d.resize(5);
  const std::string model = d.empty() ? std::string("none") : *dmodel;  // D [] = undistorted
  if (Status s = setDistortion(model, d, get(*root, "distortion_coefficients"), "", "data",
                               w.child("distortion_coefficients"), &cam);
      !s)
    return Error{s.error()};
  return ci;
}

YAML::Node rosMatrix(int rows, int cols, const double* data) {
  YAML::Node m;
  m["rows"] = rows;
  m["cols"] = cols;
  YAML::Node d(YAML::NodeType::Sequence);
  for (int i = 0; i < rows * cols; ++i) d.push_back(data[i]);
  m["data"] = d;
  return m;
}

}  // namespace

Expected<CameraInfo> readCameraInfoYaml(const std::string& path) {
  auto root = loadMap(path);
  if (!root) return Error{root.error()};
  return parseCameraInfo(&*root, Where{path, ""});
}

Expected<CameraInfo> cameraInfoFromMessage(const CameraInfoMessage& m, const std::string& source) {
  // The message is checked by the file reader's rules: the same fields in a YAML map.
  YAML::Node root;
  root["image_width"] = m.width;
  root["image_height"] = m.height;
  root["camera_matrix"] = rosMatrix(3, 3, m.K.data());
  // Uncalibrated drivers leave R all zero and the model empty: identity, no distortion.
  const bool r_zero = std::all_of(m.R.begin(), m.R.end(), [](double v) { return v == 0; });
  const std::array<double, 9> I = {1, 0, 0, 0, 1, 0, 0, 0, 1};
  root["rectification_matrix"] = rosMatrix(3, 3, r_zero ? I.data() : m.R.data());
  root["projection_matrix"] = rosMatrix(3, 4, m.P.data());
  root["distortion_model"] =
      m.distortion_model.empty() && m.D.empty() ? std::string("plumb_bob") : m.distortion_model;
  root["distortion_coefficients"] = rosMatrix(1, static_cast<int>(m.D.size()), m.D.data());
  return parseCameraInfo(&root, Where{source, ""});
}

Expected<CameraCalibration> readCameraInfoPair(const std::string& left_yaml,
                                               const std::string& right_yaml) {
  auto L = readCameraInfoYaml(left_yaml);
  if (!L) return Error{L.error()};
  auto R = readCameraInfoYaml(right_yaml);
  if (!R) return Error{R.error()};
  return stereoFromCameraInfo(*L, *R, left_yaml, right_yaml);
}

Expected<CameraCalibration> stereoFromCameraInfo(const CameraInfo& left, const CameraInfo& right,
                                                 const std::string& left_yaml,
                                                 const std::string& right_yaml) {
  const CameraInfo* L = &left;
  const CameraInfo* R = &right;
  if (L->width != R->width || L->height != R->height)
    return Error{right_yaml + ": key 'image_width'/'image_height' differs from " + left_yaml};
  const auto& Pl = L->P;
  const auto& Pr = R->P;
  if (Pl(0, 3) != 0 || Pl(1, 3) != 0 || Pl(2, 3) != 0)
    return pairError(left_yaml, "of the left camera must have a zero last column");
  if (Pr(1, 3) != 0 || Pr(2, 3) != 0)
    return pairError(right_yaml, "must have P[1][3] = P[2][3] = 0 (horizontal stereo only)");
  if (Pr(0, 3) == 0)
    return pairError(right_yaml,
                     "has no baseline (P[0][3] = 0), so the pair's extrinsics are unknown: "
                     "calibrate the two cameras as a stereo pair or write a Hermes camera file");
  const double b = -Pr(0, 3) / Pr(0, 0);
  if (!(b > 0))
    return pairError(right_yaml, "gives a negative baseline (P[0][3] = -fx' b must be < 0): "
                                 "left and right swapped?");
  const double tol = 1e-6 * Pl(0, 0);
  if (std::abs(Pl(0, 0) - Pr(0, 0)) > tol || std::abs(Pl(1, 1) - Pr(1, 1)) > tol ||
      std::abs(Pl(1, 2) - Pr(1, 2)) > tol)
    return pairError(right_yaml, "differs from the left one in fx', fy' or cy': not a "
                                 "rectified pair");

  CameraCalibration c;
  c.format = "camera_info";
  c.source = left_yaml + " + " + right_yaml;
  c.width = L->width;
  c.height = L->height;
  // Body = raw left camera. Rectified frames: p_rect = R p_raw, and the
  // rectified right camera sits at +b along the rectified left x axis.
  const SE3 T_Cl_Crectl(Mat3(L->R.transpose()), Vec3::Zero());
  const SE3 T_Crectl_Crectr(Mat3::Identity(), Vec3(b, 0, 0));
  StereoRig raw{L->camera, R->camera};
  raw.right.T_B_C = T_Cl_Crectl * T_Crectl_Crectr * SE3(R->R, Vec3::Zero());
  c.raw_stereo = raw;
  auto rectifiedCamera = [&](const Eigen::Matrix<double, 3, 4>& P, const SE3& T_B_C) {
    PinholeRadtan cam;
    cam.K = PinholeIntrinsics{P(0, 0), P(1, 1), P(0, 2), P(1, 2), c.width, c.height};
    cam.T_B_C = T_B_C;
    cam.rate_hz = 0;
    return cam;
  };
  c.stereo.left = rectifiedCamera(Pl, T_Cl_Crectl);
  c.stereo.right = rectifiedCamera(Pr, T_Cl_Crectl * T_Crectl_Crectr);
  c.rectified = true;
  if (Status s = c.validate(); !s) return Error{s.error()};
  return c;
}

Expected<CameraCalibration> rgbdFromCameraInfo(const CameraInfo& colour, double depth_scale,
                                               const std::string& source) {
  const PinholeRadtan& cam = colour.camera;
  if (cam.model != DistortionModel::kRadtan || cam.distortionCount() > 5)
    return Error{source + ": key 'distortion_model' of an RGB-D colour camera must be plumb_bob "
                          "with at most 5 coefficients (has '" + colour.distortion_model + "')"};
  if (!(depth_scale > 0))
    return Error{source + ": depth scale must be > 0 (got " + std::to_string(depth_scale) + ")"};
  CameraCalibration c;
  c.kind = CameraCalibration::Kind::kRgbd;
  c.format = "camera_info";
  c.source = source;
  c.width = colour.width;
  c.height = colour.height;
  c.rgbd.K = cam.K;
  for (int i = 0; i < 5; ++i) c.rgbd.dist[i] = cam.dist[i];
  c.rgbd.depth_scale = depth_scale;
  c.rgbd.rate_hz = 0;
  if (Status s = c.validate(); !s) return Error{s.error()};
  return c;
}

Expected<CameraCalibration> calibrationFromCameraInfo(const CameraInfoMessage& left,
                                                      const std::string& left_source,
                                                      const CameraInfoMessage* right,
                                                      const std::string& right_source,
                                                      double depth_scale) {
  auto l = cameraInfoFromMessage(left, left_source);
  if (!l) return Error{l.error()};
  if (!right) return rgbdFromCameraInfo(*l, depth_scale, left_source);
  auto r = cameraInfoFromMessage(*right, right_source);
  if (!r) return Error{r.error()};
  return stereoFromCameraInfo(*l, *r, left_source, right_source);
}

}  // namespace hermes
