#include "hermes/core/camera.h"

namespace hermes {

Vec2 PinholeRadtan::distort(const Vec2& xn) const {
  const double k1 = dist[0], k2 = dist[1], p1 = dist[2], p2 = dist[3];
  const double x = xn.x(), y = xn.y();
  const double r2 = x * x + y * y;
  const double radial = 1.0 + k1 * r2 + k2 * r2 * r2;
  return Vec2(x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x),
              y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y);
}

Vec2 PinholeRadtan::undistortNormalized(const Vec2& xd) const {
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

}  // namespace hermes
