#include "hermes/core/geometry.h"

#include <algorithm>
#include <cmath>

namespace hermes {

Mat3 hat(const Vec3& v) {
  Mat3 m;
  m << 0, -v.z(), v.y(), v.z(), 0, -v.x(), -v.y(), v.x(), 0;
  return m;
}

Mat3 expSO3(const Vec3& omega) {
  const double theta = omega.norm();
  if (theta < 1e-10) return Mat3::Identity() + hat(omega);
  return Eigen::AngleAxisd(theta, omega / theta).toRotationMatrix();
}

Vec3 logSO3(const Mat3& R) {
  Eigen::AngleAxisd aa(Quat(R).normalized());
  double angle = aa.angle();
  Vec3 axis = aa.axis();
  if (angle > M_PI) {
    angle = 2.0 * M_PI - angle;
    axis = -axis;
  }
  return axis * angle;
}

double rotationAngle(const Mat3& R) {
  // 2 atan2(|v|, |w|) of the quaternion resolves tiny angles, unlike acos(trace).
  const Quat q(R);
  return 2.0 * std::atan2(q.vec().norm(), std::abs(q.w()));
}

namespace {
// Left Jacobian of SO(3) and its inverse, used by the SE(3) exp/log.
Mat3 leftJacobianSO3(const Vec3& phi) {
  const double theta = phi.norm();
  const Mat3 K = hat(phi);
  if (theta < 1e-8) return Mat3::Identity() + 0.5 * K;
  const double t2 = theta * theta;
  return Mat3::Identity() + (1.0 - std::cos(theta)) / t2 * K +
         (theta - std::sin(theta)) / (t2 * theta) * K * K;
}
}  // namespace

SE3::SE3(const Mat4& T) : SE3(Mat3(T.topLeftCorner<3, 3>()), Vec3(T.topRightCorner<3, 1>())) {}

SE3 SE3::exp(const Vec6& xi) {
  const Vec3 rho = xi.head<3>();
  const Vec3 phi = xi.tail<3>();
  return SE3(expSO3(phi), leftJacobianSO3(phi) * rho);
}

Vec6 SE3::log() const {
  const Vec3 phi = logSO3(rotation());
  Vec6 xi;
  xi.head<3>() = leftJacobianSO3(phi).inverse() * t_;
  xi.tail<3>() = phi;
  return xi;
}

Mat4 SE3::matrix() const {
  Mat4 T = Mat4::Identity();
  T.topLeftCorner<3, 3>() = rotation();
  T.topRightCorner<3, 1>() = t_;
  return T;
}

SE3 SE3::inverse() const {
  const Quat qi = q_.conjugate();
  return SE3(qi, -(qi * t_));
}

Mat6 SE3::adjoint() const {
  Mat6 A = Mat6::Zero();
  const Mat3 R = rotation();
  A.topLeftCorner<3, 3>() = R;
  A.topRightCorner<3, 3>() = hat(t_) * R;
  A.bottomRightCorner<3, 3>() = R;
  return A;
}

double angularDistance(const SE3& a, const SE3& b) {
  return rotationAngle(a.rotation().transpose() * b.rotation());
}

double translationalDistance(const SE3& a, const SE3& b) {
  return (a.translation() - b.translation()).norm();
}

}  // namespace hermes
