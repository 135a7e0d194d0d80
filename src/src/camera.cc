#include "hermes/core/camera.h"

#include <algorithm>
#include <cmath>

namespace hermes {
namespace {

// theta_d(theta) of the equidistant model and its derivative.
double equidistantThetaD(const std::array<double, 8>& k, double th, double* dth = nullptr) {
  const double t2 = th * th, t4 = t2 * t2, t6 = t4 * t2, t8 = t4 * t4;
  if (dth) *dth = 1.0 + 3.0 * k[0] * t2 + 5.0 * k[1] * t4 + 7.0 * k[2] * t6 + 9.0 * k[3] * t8;
  return th * (1.0 + k[0] * t2 + k[1] * t4 + k[2] * t6 + k[3] * t8);
}

}  // namespace

const char* toString(DistortionModel m) {
  switch (m) {
    case DistortionModel::kRadtan: return "radtan";
    case DistortionModel::kEquidistant: return "equidistant";
  }
  return "?";
}

int PinholeRadtan::distortionCount() const {
  if (model == DistortionModel::kEquidistant) return 4;
  if (dist[5] != 0 || dist[6] != 0 || dist[7] != 0) return 8;
  return dist[4] != 0 ? 5 : 4;
}

bool PinholeRadtan::hasDistortion() const {
  for (double d : dist)
    if (d != 0) return true;
  return false;
}

Vec2 PinholeRadtan::distort(const Vec2& xn) const {
  if (model == DistortionModel::kEquidistant) {
    const double r = xn.norm();
    if (r < 1e-12) return xn;
    return xn * (equidistantThetaD(dist, std::atan(r)) / r);
  }
  const double k1 = dist[0], k2 = dist[1], p1 = dist[2], p2 = dist[3];
  const double x = xn.x(), y = xn.y();
  const double r2 = x * x + y * y;
  double radial = 1.0 + k1 * r2 + k2 * r2 * r2;
  if (distortionCount() > 4) {  // plumb_bob k3 / rational_polynomial k4..k6
    const double r4 = r2 * r2, r6 = r4 * r2;
    radial = (radial + dist[4] * r6) / (1.0 + dist[5] * r2 + dist[6] * r4 + dist[7] * r6);
  }
  return Vec2(x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x),
              y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y);
}

Vec2 PinholeRadtan::undistortNormalized(const Vec2& xd) const {
  if (model == DistortionModel::kEquidistant) {
    const double th_d = xd.norm();
    if (th_d < 1e-12) return xd;
    const double kMaxTheta = 1.5707963267948966 - 1e-6;  // beyond: no pinhole coordinates
    double th = std::min(th_d, kMaxTheta);
    for (int i = 0; i < 30; ++i) {
      double dth = 1;
      const double err = equidistantThetaD(dist, th, &dth) - th_d;
      if (std::abs(err) < 1e-14 || !(dth > 0)) break;
      th = std::clamp(th - err / dth, 0.0, kMaxTheta);
    }
    return xd * (std::tan(th) / th_d);
  }
  Vec2 x = xd;
  for (int i = 0; i < 30; ++i) {
    const Vec2 err = distort(x) - xd;
    if (err.squaredNorm() < 1e-24) break;
    // Numerical Jacobian of distort(); cheap and robust for these lenses.
    const double h = 1e-7;
    Eigen::Matrix2d J;
    J.col(0) = (distort(x + Vec2(h, 0)) - distort(x - Vec2(h, 0))) / (2 * h);
    J.col(1) = (distort(x + Vec2(0, h)) - distort(x - Vec2(0, h))) / (2 * h);
    x -= J.inverse() * err;
  }
  return x;
}

bool PinholeRadtan::project(const Vec3& p_C, Vec2* uv) const {
  if (p_C.z() <= 1e-9) return false;
  const Vec2 d = distort(Vec2(p_C.x() / p_C.z(), p_C.y() / p_C.z()));
  *uv = Vec2(K.fx * d.x() + K.cx, K.fy * d.y() + K.cy);
  return true;
}

Vec2 PinholeRadtan::undistortPixel(const Vec2& uv, const PinholeIntrinsics& out) const {
  const Vec2 xd((uv.x() - K.cx) / K.fx, (uv.y() - K.cy) / K.fy);
  const Vec2 xn = undistortNormalized(xd);
  return Vec2(out.fx * xn.x() + out.cx, out.fy * xn.y() + out.cy);
}

bool RgbdCamera::hasDistortion() const {
  for (double d : dist)
    if (d != 0) return true;
  return false;
}

PinholeRadtan RgbdCamera::colourCamera() const {
  PinholeRadtan c;
  c.K = K;
  for (std::size_t i = 0; i < dist.size(); ++i) c.dist[i] = dist[i];
  c.T_B_C = T_B_C;
  c.rate_hz = rate_hz;
  return c;
}

}  // namespace hermes
