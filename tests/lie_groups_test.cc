// Jacobians of SE(2), SE(3) and the relative-pose error against numerical differentiation.
#include <limits>
#include <random>

#include <gtest/gtest.h>

#include "arbor_slam/core/finite_pose.h"
#include "arbor_slam/core/relative_pose_factor.h"
#include "arbor_slam/core/se2.h"
#include "arbor_slam/core/se3.h"
#include "arbor_slam/core/so3.h"

namespace arbor {
namespace {

template <class G>
G randomPose(std::mt19937_64& rng, double scale = 1.0) {
  std::normal_distribution<double> n(0.0, scale);
  typename G::Tangent tau;
  for (int k = 0; k < G::kDoF; ++k) tau(k) = n(rng);
  return G::Exp(tau);
}

// Central differences of f(x ⊞ τ) in the local coordinates of f(x).
template <class G, class F>
typename G::Jacobian numericalJacobian(const F& f, const G& x) {
  typename G::Jacobian J;
  const double h = 1e-6;
  const G fx = f(x);
  for (int k = 0; k < G::kDoF; ++k) {
    typename G::Tangent d = G::Tangent::Zero();
    d(k) = h;
    const auto plus = fx.localCoordinates(f(x.retract(d)));
    const auto minus = fx.localCoordinates(f(x.retract(-d)));
    J.col(k) = (plus - minus) / (2.0 * h);
  }
  return J;
}

template <class G>
class LieGroupTest : public ::testing::Test {};
using Groups = ::testing::Types<SE2, SE3>;
TYPED_TEST_SUITE(LieGroupTest, Groups);

TYPED_TEST(LieGroupTest, ExpLogRoundTrip) {
  using G = TypeParam;
  std::mt19937_64 rng(1);
  for (int trial = 0; trial < 50; ++trial) {
    const G x = randomPose<G>(rng, 0.8);
    const G y = G::Exp(x.Log());
    EXPECT_LT(x.localCoordinates(y).norm(), 1e-10);
  }
}

TYPED_TEST(LieGroupTest, RetractLocalCoordinatesRoundTrip) {
  using G = TypeParam;
  std::mt19937_64 rng(2);
  for (int trial = 0; trial < 50; ++trial) {
    const G x = randomPose<G>(rng);
    const G y = randomPose<G>(rng);
    const G z = x.retract(x.localCoordinates(y));
    EXPECT_LT(y.localCoordinates(z).norm(), 1e-10);
  }
}

TYPED_TEST(LieGroupTest, ComposeInverseIdentity) {
  using G = TypeParam;
  std::mt19937_64 rng(3);
  const G x = randomPose<G>(rng);
  EXPECT_LT(x.compose(x.inverse()).Log().norm(), 1e-12);
  EXPECT_LT(x.between(x).Log().norm(), 1e-12);
}

TYPED_TEST(LieGroupTest, AdjointMovesPerturbation) {
  using G = TypeParam;
  std::mt19937_64 rng(4);
  const G x = randomPose<G>(rng);
  typename G::Tangent tau = randomPose<G>(rng, 0.3).Log();
  const G lhs = x.compose(G::Exp(tau));
  const G rhs = G::Exp(x.Adj() * tau).compose(x);
  EXPECT_LT(lhs.localCoordinates(rhs).norm(), 1e-10);
}

TYPED_TEST(LieGroupTest, ComposeInverseJacobians) {
  using G = TypeParam;
  std::mt19937_64 rng(5);
  for (int trial = 0; trial < 20; ++trial) {
    const G a = randomPose<G>(rng);
    const G b = randomPose<G>(rng);
    typename G::Jacobian Ja, Jb, Jinv, Jba, Jbb;
    a.compose(b, &Ja, &Jb);
    a.inverse(&Jinv);
    a.between(b, &Jba, &Jbb);
    EXPECT_LT((Ja - numericalJacobian<G>([&](const G& x) { return x.compose(b); }, a)).norm(),
              1e-6);
    EXPECT_LT((Jb - numericalJacobian<G>([&](const G& x) { return a.compose(x); }, b)).norm(),
              1e-6);
    EXPECT_LT((Jinv - numericalJacobian<G>([](const G& x) { return x.inverse(); }, a)).norm(),
              1e-6);
    EXPECT_LT((Jba - numericalJacobian<G>([&](const G& x) { return x.between(b); }, a)).norm(),
              1e-6);
    EXPECT_LT((Jbb - numericalJacobian<G>([&](const G& x) { return a.between(x); }, b)).norm(),
              1e-6);
  }
}

TYPED_TEST(LieGroupTest, ExpLogJacobians) {
  using G = TypeParam;
  std::mt19937_64 rng(6);
  for (double scale : {1e-9, 1e-3, 0.5, 1.2}) {
    const typename G::Tangent tau = randomPose<G>(rng, 1.0).Log().normalized() * scale;
    typename G::Jacobian Jr, Jr_inv;
    const G x = G::Exp(tau, &Jr);
    x.Log(&Jr_inv);
    // Numerical right Jacobian of Exp: Exp(τ)⁻¹ Exp(τ + h eₖ) ≈ Exp(Jr h eₖ).
    typename G::Jacobian N;
    const double h = 1e-6;
    for (int k = 0; k < G::kDoF; ++k) {
      typename G::Tangent d = G::Tangent::Zero();
      d(k) = h;
      N.col(k) = (x.between(G::Exp(tau + d)).Log() - x.between(G::Exp(tau - d)).Log()) / (2 * h);
    }
    EXPECT_LT((Jr - N).norm(), 1e-6) << "scale " << scale;
    EXPECT_LT((Jr * Jr_inv - G::Jacobian::Identity()).norm(), 1e-8) << "scale " << scale;
  }
}

TYPED_TEST(LieGroupTest, RelativePoseErrorJacobians) {
  using G = TypeParam;
  std::mt19937_64 rng(7);
  for (int trial = 0; trial < 30; ++trial) {
    const G xi = randomPose<G>(rng, 2.0);
    const G xj = randomPose<G>(rng, 2.0);
    // Measurements both near and far from the current relative pose.
    const G z = trial % 2 ? xi.between(xj).compose(randomPose<G>(rng, 0.1)) : randomPose<G>(rng);
    typename G::Jacobian Ji, Jj;
    relativePoseError(z, xi, xj, &Ji, &Jj);
    typename G::Jacobian Ni, Nj;
    const double h = 1e-6;
    for (int k = 0; k < G::kDoF; ++k) {
      typename G::Tangent d = G::Tangent::Zero();
      d(k) = h;
      Ni.col(k) =
          (relativePoseError(z, xi.retract(d), xj) - relativePoseError(z, xi.retract(-d), xj)) /
          (2 * h);
      Nj.col(k) =
          (relativePoseError(z, xi, xj.retract(d)) - relativePoseError(z, xi, xj.retract(-d))) /
          (2 * h);
    }
    EXPECT_LT((Ji - Ni).norm(), 1e-5) << "trial " << trial;
    EXPECT_LT((Jj - Nj).norm(), 1e-5) << "trial " << trial;
  }
}

TEST(LieGroups, AllFiniteSeesEveryNumber) {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const double inf = std::numeric_limits<double>::infinity();
  EXPECT_TRUE(allFinite(SE2(1e308, 1e308, 0.5)));  // finite however large
  EXPECT_FALSE(allFinite(SE2(nan, 0, 0)));
  EXPECT_FALSE(allFinite(SE2(0, inf, 0)));
  EXPECT_FALSE(allFinite(SE2(0, 0, nan)));  // cos and sin of a NaN angle
  const Eigen::Quaterniond q(0.5, 0.5, 0.5, 0.5);
  EXPECT_TRUE(allFinite(SE3(q, Eigen::Vector3d(1e308, -1e308, 3))));
  EXPECT_FALSE(allFinite(SE3(q, Eigen::Vector3d(0, nan, 0))));
  EXPECT_FALSE(allFinite(SE3(Eigen::Quaterniond(nan, 0, 0, 1), Eigen::Vector3d::Zero())));
}

TEST(RelativePoseError, ConventionMatchesDefinition) {
  // δ = z⁻¹(xᵢ⁻¹xⱼ); e = [t(δ); θ(δ)] in 2D.
  const SE2 xi(1.0, 2.0, 0.3), xj(2.0, 1.0, -2.9), z(0.5, -1.0, 3.0);
  const SE2 delta = z.inverse().compose(xi.inverse().compose(xj));
  const Eigen::Vector3d e = relativePoseError(z, xi, xj);
  EXPECT_NEAR(e(0), delta.x(), 1e-12);
  EXPECT_NEAR(e(1), delta.y(), 1e-12);
  EXPECT_NEAR(e(2), wrapAngle(0.3 * 0 + (-2.9 - 0.3 - 3.0)), 1e-12);
  EXPECT_GT(e(2), -M_PI);
  EXPECT_LE(e(2), M_PI);
}

TEST(RelativePoseError, QuaternionSignIsCanonical) {
  // A rotation of nearly 2π about z has q_w < 0 in some representations; e uses q_w ≥ 0.
  const SE3 xi(Eigen::Quaterniond(Eigen::AngleAxisd(3.1, Eigen::Vector3d::UnitZ())), {0, 0, 0});
  const SE3 xj(Eigen::Quaterniond(Eigen::AngleAxisd(-3.1, Eigen::Vector3d::UnitZ())), {0, 0, 0});
  const Eigen::Matrix<double, 6, 1> e = relativePoseError(SE3(), xi, xj);
  // The relative rotation is 2π − 6.2 ≈ 0.083 rad about z: 2·sin(θ/2) ≈ θ.
  EXPECT_NEAR(e(5), 2.0 * std::sin((2 * M_PI - 6.2) / 2), 1e-12);
}

TEST(So3, LogNearPi) {
  const Eigen::Vector3d axis = Eigen::Vector3d(1, 2, 3).normalized();
  const Eigen::Vector3d w = axis * (M_PI - 1e-7);
  EXPECT_LT((so3::Log(so3::Exp(w)) - w).norm(), 1e-9);
}

}  // namespace
}  // namespace arbor
