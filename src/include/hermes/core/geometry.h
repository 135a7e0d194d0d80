// SO(3) / SE(3) helpers. Transforms are named T_<to>_<from>: T_W_C maps points
// expressed in the camera frame C into the world frame W.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>

namespace hermes {

using Vec2 = Eigen::Vector2d;
using Vec3 = Eigen::Vector3d;
using Vec6 = Eigen::Matrix<double, 6, 1>;
using Mat3 = Eigen::Matrix3d;
using Mat4 = Eigen::Matrix4d;
using Mat6 = Eigen::Matrix<double, 6, 6>;
using Quat = Eigen::Quaterniond;

/// Skew-symmetric matrix [v]x with [v]x w = v x w.
Mat3 hat(const Vec3& v);

/// SO(3) exponential map (Rodrigues), small-angle safe.
Mat3 expSO3(const Vec3& omega);

/// SO(3) logarithm: rotation vector of R, safe near 0 and pi.
Vec3 logSO3(const Mat3& R);

/// Rotation angle of R in radians, in [0, pi].
double rotationAngle(const Mat3& R);

/// Rigid transform; value type, always normalised rotation.
class SE3 {
 public:
  SE3() : q_(Quat::Identity()), t_(Vec3::Zero()) {}
  SE3(const Quat& q, const Vec3& t) : q_(q.normalized()), t_(t) {}
  SE3(const Mat3& R, const Vec3& t) : q_(Quat(R).normalized()), t_(t) {}
  explicit SE3(const Mat4& T);

  static SE3 identity() { return SE3(); }
  /// From a stored unit quaternion, taken as it is (no renormalisation): a pose
  /// written bit for bit reads back bit for bit (tracking recordings).
  static SE3 fromUnitQuat(const Quat& q, const Vec3& t) {
    SE3 T;
    T.q_ = q;
    T.t_ = t;
    return T;
  }
  /// Exponential map; tangent ordered [rho (translation); phi (rotation)].
  static SE3 exp(const Vec6& xi);
  /// Logarithm with the same ordering as exp().
  Vec6 log() const;

  const Quat& quat() const { return q_; }
  Mat3 rotation() const { return q_.toRotationMatrix(); }
  const Vec3& translation() const { return t_; }
  Mat4 matrix() const;
  SE3 inverse() const;

  SE3 operator*(const SE3& o) const { return SE3(q_ * o.q_, q_ * o.t_ + t_); }
  Vec3 operator*(const Vec3& p) const { return q_ * p + t_; }

  /// 6x6 adjoint (same ordering as exp()).
  Mat6 adjoint() const;

 private:
  Quat q_;
  Vec3 t_;
};

/// Rotation angle (rad) and translation distance (m) between two poses.
double angularDistance(const SE3& a, const SE3& b);
double translationalDistance(const SE3& a, const SE3& b);

}  // namespace hermes
