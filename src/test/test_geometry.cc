#include <gtest/gtest.h>

#include <random>

#include "hermes/core/geometry.h"

using namespace hermes;

TEST(Geometry, ExpLogRoundTrip) {
  std::mt19937 rng(1);
  std::uniform_real_distribution<double> u(-1.5, 1.5);
  for (int i = 0; i < 200; ++i) {
    Vec6 xi;
    for (int k = 0; k < 6; ++k) xi[k] = u(rng);
    const SE3 T = SE3::exp(xi);
    EXPECT_LT((T.log() - xi).norm(), 1e-9) << i;
  }
}

TEST(Geometry, InverseAndCompose) {
  const SE3 T_W_C(expSO3(Vec3(0.1, -0.3, 0.7)), Vec3(1, 2, 3));
  const SE3 I = T_W_C * T_W_C.inverse();
  EXPECT_LT((I.matrix() - Mat4::Identity()).norm(), 1e-12);
  const Vec3 p_C(0.5, -0.2, 4.0);
  EXPECT_LT(((T_W_C * p_C) - (T_W_C.rotation() * p_C + T_W_C.translation())).norm(), 1e-12);
}

TEST(Geometry, AdjointMatchesConjugation) {
  const SE3 T(expSO3(Vec3(0.4, 0.2, -0.1)), Vec3(-1, 0.5, 2));
  Vec6 xi;
  xi << 0.1, -0.2, 0.3, 0.05, 0.02, -0.04;
  const SE3 lhs = T * SE3::exp(xi) * T.inverse();
  const SE3 rhs = SE3::exp(T.adjoint() * xi);
  EXPECT_LT((lhs.matrix() - rhs.matrix()).norm(), 1e-9);
}

TEST(Geometry, LogNearPi) {
  const Vec3 w = Vec3(0, 0, 1) * (M_PI - 1e-9);
  EXPECT_NEAR(logSO3(expSO3(w)).norm(), M_PI, 1e-6);
  EXPECT_NEAR(rotationAngle(expSO3(Vec3(0.3, 0, 0))), 0.3, 1e-12);
}

TEST(Geometry, RotationAngleResolvesTinyAngles) {
  EXPECT_NEAR(rotationAngle(expSO3(Vec3(1e-9, 0, 0))), 1e-9, 1e-15);
  EXPECT_NEAR(rotationAngle(expSO3(Vec3(0, 2.5, 0))), 2.5, 1e-12);
}
