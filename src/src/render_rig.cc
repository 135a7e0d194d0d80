// Built-in rigs: real EuRoC VI-Sensor calibration (same rig for every sequence,
// values from the dataset's cam0/cam1 sensor.yaml) and a TUM-like RGB-D camera.
#include "hermes/core/render/rig.h"

namespace hermes {
namespace render {

namespace {
SE3 fromRowMajor(const double m[16]) {
  Mat4 T;
  for (int r = 0; r < 4; ++r)
    for (int c = 0; c < 4; ++c) T(r, c) = m[4 * r + c];
  return SE3(T);
}
}  // namespace

PinholeRadtan eurocCam0() {
  static const double kT_BS[16] = {0.0148655429818, -0.999880929698, 0.00414029679422, -0.0216401454975,
                                   0.999557249008,  0.0149672133247, 0.025715529948,   -0.064676986768,
                                   -0.0257744366974, 0.00375618835797, 0.999660727178, 0.00981073058949,
                                   0.0, 0.0, 0.0, 1.0};
  PinholeRadtan c;
  c.K = PinholeIntrinsics{458.654, 457.296, 367.215, 248.375, 752, 480};
  c.dist = {-0.28340811, 0.07395907, 0.00019359, 1.76187114e-05};
  c.T_B_C = fromRowMajor(kT_BS);
  c.rate_hz = 20.0;
  return c;
}

PinholeRadtan eurocCam1() {
  static const double kT_BS[16] = {0.0125552670891, -0.999755099723, 0.0182237714554, -0.0198435579556,
                                   0.999598781151,  0.0130119051815, 0.0251588363115, 0.0453689425024,
                                   -0.0253898008918, 0.0179005838253, 0.999517347078, 0.00786212447038,
                                   0.0, 0.0, 0.0, 1.0};
  PinholeRadtan c;
  c.K = PinholeIntrinsics{457.587, 456.134, 379.999, 255.238, 752, 480};
  c.dist = {-0.28368365, 0.07451284, -0.00010473, -3.55590700e-05};
  c.T_B_C = fromRowMajor(kT_BS);
  c.rate_hz = 20.0;
  return c;
}

RgbdCamera defaultRgbd() {
  RgbdCamera c;
  c.K = PinholeIntrinsics{525.0, 525.0, 319.5, 239.5, 640, 480};
  c.depth_scale = 5000.0;
  c.T_B_C = eurocCam0().T_B_C;
  c.rate_hz = 30.0;
  return c;
}

PinholeIntrinsics scaleIntrinsics(const PinholeIntrinsics& K, int width, int height) {
  const double sx = static_cast<double>(width) / K.width, sy = static_cast<double>(height) / K.height;
  PinholeIntrinsics o;
  o.fx = K.fx * sx;
  o.fy = K.fy * sy;
  o.cx = (K.cx + 0.5) * sx - 0.5;
  o.cy = (K.cy + 0.5) * sy - 0.5;
  o.width = width;
  o.height = height;
  return o;
}

}  // namespace render
}  // namespace hermes
