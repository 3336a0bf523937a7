// Every factor's Jacobians against central differences of its error under x ⊞ τ (the solvers'
// retraction), at random poses; Factor<G>'s common whitened linearisation against each
// factor's own (zero-padded rows for the position prior), and ‖r‖² against the cost.
#include <random>
#include <vector>

#include <gtest/gtest.h>
#include <Eigen/Core>

#include "arbor_slam/core/factor.h"
#include "arbor_slam/core/prior_factors.h"
#include "arbor_slam/core/relative_pose_factor.h"
#include "arbor_slam/tests/random_graphs.h"

namespace arbor {
namespace {

using testing::randomInformation;
using testing::randomTangent;

constexpr double kStep = 1e-6;       // central-difference step
constexpr double kTolerance = 1e-6;  // on each Jacobian entry

template <class G>
G randomPose(std::mt19937_64& rng) {
  return G::Exp(randomTangent<G>(rng, 3.0, 1.0));
}

/// ∂f(x ⊞ τ)/∂τ at τ = 0 by central differences, f: G → ℝᵐ.
template <class G, class F>
Eigen::MatrixXd numericJacobian(const G& x, const F& f) {
  const Eigen::VectorXd f0 = f(x);
  Eigen::MatrixXd J(f0.size(), G::kDoF);
  for (int k = 0; k < G::kDoF; ++k) {
    typename G::Tangent tau = G::Tangent::Zero();
    tau(k) = kStep;
    const Eigen::VectorXd plus = f(x.retract(tau)), minus = f(x.retract(-tau));
    J.col(k) = (plus - minus) / (2 * kStep);
  }
  return J;
}

/// A random information matrix of size m (dense, positive definite).
template <int m>
Eigen::Matrix<double, m, m> randomSpd(std::mt19937_64& rng) {
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  Eigen::Matrix<double, m, m> b;
  for (int k = 0; k < b.size(); ++k) b.data()[k] = u(rng);
  return b * b.transpose() + 5.0 * Eigen::Matrix<double, m, m>::Identity();
}

template <class G>
class FactorTest : public ::testing::Test {};
using Groups = ::testing::Types<SE2, SE3>;
TYPED_TEST_SUITE(FactorTest, Groups);

TYPED_TEST(FactorTest, RelativePoseJacobiansMatchCentralDifferences) {
  using G = TypeParam;
  std::mt19937_64 rng(1);
  for (int trial = 0; trial < 20; ++trial) {
    const G xi = randomPose<G>(rng);
    const G xj = xi.compose(G::Exp(randomTangent<G>(rng, 1.0, 0.5)));
    const G z = xi.between(xj).retract(randomTangent<G>(rng, 0.2, 0.2));
    typename G::Jacobian Ji, Jj;
    relativePoseError(z, xi, xj, &Ji, &Jj);
    const Eigen::MatrixXd Ni = numericJacobian(
        xi, [&](const G& x) -> Eigen::VectorXd { return relativePoseError(z, x, xj); });
    const Eigen::MatrixXd Nj = numericJacobian(
        xj, [&](const G& x) -> Eigen::VectorXd { return relativePoseError(z, xi, x); });
    EXPECT_LT((Ji - Ni).cwiseAbs().maxCoeff(), kTolerance) << "trial " << trial << "\n" << Ji;
    EXPECT_LT((Jj - Nj).cwiseAbs().maxCoeff(), kTolerance) << "trial " << trial << "\n" << Jj;
    EXPECT_GT(Ji.norm(), 0.5);  // not trivially zero
  }
}

TYPED_TEST(FactorTest, PosePriorJacobianMatchesCentralDifferencesWithAndWithoutOffset) {
  using G = TypeParam;
  std::mt19937_64 rng(2);
  for (int trial = 0; trial < 20; ++trial) {
    const G x = randomPose<G>(rng);
    const bool with_offset = trial % 2 == 1;
    const G offset = with_offset ? G::Exp(randomTangent<G>(rng, 0.5, 0.5)) : G::Identity();
    const G z = x.compose(offset).retract(randomTangent<G>(rng, 0.2, 0.2));
    const auto prior = PosePriorFactor<G>::make(3, z, randomSpd<G::kDoF>(rng), offset);
    EXPECT_EQ(prior.has_offset, with_offset);
    typename PosePriorFactor<G>::Jacobian J;
    const auto e = prior.error(x, &J);
    const Eigen::MatrixXd N =
        numericJacobian(x, [&](const G& y) -> Eigen::VectorXd { return prior.error(y); });
    EXPECT_LT((J - N).cwiseAbs().maxCoeff(), kTolerance) << "trial " << trial << "\n" << J;
    // The error is the relative-pose error from the identity to x·o.
    EXPECT_LT((e - relativePoseError(z, G::Identity(), x.compose(offset))).norm(), 1e-12);
    EXPECT_GT(J.norm(), 0.5);
  }
}

TYPED_TEST(FactorTest, PositionPriorJacobianMatchesCentralDifferences) {
  using G = TypeParam;
  constexpr int d = G::kDim;
  std::mt19937_64 rng(3);
  for (int trial = 0; trial < 20; ++trial) {
    const G x = randomPose<G>(rng);
    const typename G::Translation p =
        x.translation() + randomTangent<G>(rng, 0.5, 0.0).template head<d>();
    const auto prior = PositionPriorFactor<G>::make(4, p, randomSpd<d>(rng));
    typename PositionPriorFactor<G>::Jacobian J;
    const auto e = prior.error(x, &J);
    const Eigen::MatrixXd N =
        numericJacobian(x, [&](const G& y) -> Eigen::VectorXd { return prior.error(y); });
    ASSERT_EQ(N.rows(), d);
    EXPECT_LT((J - N).cwiseAbs().maxCoeff(), kTolerance) << "trial " << trial << "\n" << J;
    EXPECT_LT((e - (x.translation() - p)).norm(), 1e-12);
    // Rotating the pose does not move its position: the rotational columns vanish.
    EXPECT_EQ(J.template rightCols<G::kDoF - d>().norm(), 0.0);
  }
}

// Factor<G>::linearize against each factor's own linearisation; ‖r‖² = eᵀΩe = cost.
TYPED_TEST(FactorTest, CommonLinearizationEqualsEachFactorsOwn) {
  using G = TypeParam;
  constexpr int D = G::kDoF, d = G::kDim;
  std::mt19937_64 rng(4);
  for (int trial = 0; trial < 10; ++trial) {
    std::vector<G> x;
    for (int k = 0; k < 3; ++k) x.push_back(randomPose<G>(rng));
    const auto edge =
        RelativePoseEdge<G>::make(2, 0, x[2].between(x[0]).retract(randomTangent<G>(rng, 0.3, 0.3)),
                                  randomInformation<G>(rng));
    const auto pose_prior = PosePriorFactor<G>::make(
        1, x[1].retract(randomTangent<G>(rng, 0.3, 0.3)), randomSpd<D>(rng),
        trial % 2 ? G::Exp(randomTangent<G>(rng, 0.4, 0.4)) : G::Identity());
    const auto position_prior = PositionPriorFactor<G>::make(
        2, x[2].translation() + randomTangent<G>(rng, 0.5, 0.0).template head<d>(),
        randomSpd<d>(rng));
    typename Factor<G>::Linearization lin;

    const Factor<G> fe(edge);
    EXPECT_EQ(fe.kind(), FactorKind::kRelativePose);
    EXPECT_EQ(fe.arity(), 2);
    EXPECT_EQ(fe.key(0), 2);
    EXPECT_EQ(fe.key(1), 0);
    fe.linearize(x, &lin);
    typename RelativePoseEdge<G>::Matrix Ai, Aj;
    typename RelativePoseEdge<G>::Vector r;
    edge.linearize(x[2], x[0], &Ai, &Aj, &r);
    EXPECT_EQ(lin.A[0], Ai);
    EXPECT_EQ(lin.A[1], Aj);
    EXPECT_EQ(lin.r, r);
    EXPECT_NEAR(lin.r.squaredNorm(), fe.cost(x), 1e-9 * fe.cost(x));
    EXPECT_NEAR(fe.cost(x), edge.cost(x[2], x[0]), 1e-12 * fe.cost(x));

    const Factor<G> fp(pose_prior);
    EXPECT_EQ(fp.kind(), FactorKind::kPosePrior);
    EXPECT_EQ(fp.arity(), 1);
    EXPECT_EQ(fp.key(0), 1);
    fp.linearize(x, &lin);
    typename PosePriorFactor<G>::Jacobian A;
    typename PosePriorFactor<G>::Vector rp;
    pose_prior.linearize(x[1], &A, &rp);
    EXPECT_EQ(lin.A[0], A);
    EXPECT_EQ(lin.r, rp);
    EXPECT_GT(fp.cost(x), 0.0);
    EXPECT_NEAR(lin.r.squaredNorm(), fp.cost(x), 1e-9 * fp.cost(x));
    EXPECT_NEAR(fp.cost(x), pose_prior.cost(x[1]), 1e-12 * fp.cost(x));

    const Factor<G> fq(position_prior);
    EXPECT_EQ(fq.kind(), FactorKind::kPositionPrior);
    EXPECT_EQ(fq.arity(), 1);
    EXPECT_EQ(fq.key(0), 2);
    lin.A[0].setConstant(7.0);  // stale values must be overwritten by the padding
    lin.r.setConstant(7.0);
    fq.linearize(x, &lin);
    typename PositionPriorFactor<G>::Jacobian Aq;
    typename PositionPriorFactor<G>::Vector rq;
    position_prior.linearize(x[2], &Aq, &rq);
    EXPECT_EQ(Eigen::MatrixXd(lin.A[0].template topRows<d>()), Eigen::MatrixXd(Aq));
    EXPECT_EQ(Eigen::VectorXd(lin.r.template head<d>()), Eigen::VectorXd(rq));
    EXPECT_EQ(lin.A[0].template bottomRows<D - d>().norm(), 0.0);
    EXPECT_EQ(lin.r.template tail<D - d>().norm(), 0.0);
    EXPECT_GT(fq.cost(x), 0.0);
    EXPECT_NEAR(lin.r.squaredNorm(), fq.cost(x), 1e-9 * fq.cost(x));
    EXPECT_NEAR(fq.cost(x), position_prior.cost(x[2]), 1e-12 * fq.cost(x));
    // The padded block gives the same normal-equation terms as the factor's own.
    EXPECT_LT((lin.A[0].transpose() * lin.A[0] - Aq.transpose() * Aq).norm(), 1e-12);
    EXPECT_LT((lin.A[0].transpose() * lin.r - Aq.transpose() * rq).norm(), 1e-12);
  }
}

}  // namespace
}  // namespace arbor
