// Factors of your own (core/factor_model.h, core/autodiff_factor.h, core/custom_factor.h): the
// example factors' Jacobians against central differences under x ⊞ τ, analytic against
// autodiff, Factor<G>'s whitened padded linearisation, the incremental smoother against a dense
// and a batch Gauss–Newton step after every update (1e-9), batch LM, the gauge, a robust kernel
// on a custom factor, marginal covariances, and the refusals (bad Ω, residual too long, bad keys,
// the g2o writer, the certifiable solver).
#include <cmath>
#include <memory>
#include <random>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <Eigen/Cholesky>
#include <Eigen/Core>

#include "arbor/bayestree/incremental_smoother.h"
#include "arbor/bayestree/online_smoother.h"
#include "arbor/core/batch_solver.h"
#include "arbor/core/custom_factor.h"
#include "arbor/core/example_factors.h"
#include "arbor/core/factor.h"
#include "arbor/core/normal_equations.h"
#include "arbor/core/sesync_problem.h"
#include "arbor/io/pose_graph_file.h"
#include "arbor/tests/random_graphs.h"

namespace arbor {
namespace {

using testing::diagonalInformation;
using testing::randomTangent;

constexpr double kStep = 1e-6;
constexpr double kTolerance = 1e-6;

template <class G>
G randomPose(std::mt19937_64& rng) {
  return G::Exp(randomTangent<G>(rng, 3.0, 1.0));
}

template <int m>
Eigen::Matrix<double, m, m> randomSpd(std::mt19937_64& rng) {
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  Eigen::Matrix<double, m, m> b;
  for (int k = 0; k < b.size(); ++k) b.data()[k] = u(rng);
  return b * b.transpose() + 5.0 * Eigen::Matrix<double, m, m>::Identity();
}

template <class G>
Eigen::Matrix<double, G::kDim, 1> randomPoint(std::mt19937_64& rng, double scale) {
  std::uniform_real_distribution<double> u(-scale, scale);
  Eigen::Matrix<double, G::kDim, 1> p;
  for (int k = 0; k < G::kDim; ++k) p(k) = u(rng);
  return p;
}

/// Every Jacobian of f at x against central differences of its error under x_k ⊞ τ.
template <class G>
void expectJacobiansMatch(const CustomFactor<G>& f, std::vector<G> x) {
  typename FactorModel<G>::Jacobians J;
  const Eigen::VectorXd e0 = f.error(x, &J);
  ASSERT_EQ(e0.size(), f.rows());
  for (int k = 0; k < f.arity(); ++k) {
    const int key = k == 0 ? f.i : f.j;
    Eigen::MatrixXd numeric(f.rows(), G::kDoF);
    for (int c = 0; c < G::kDoF; ++c) {
      typename G::Tangent tau = G::Tangent::Zero();
      tau(c) = kStep;
      std::vector<G> plus = x, minus = x;
      plus[key] = x[key].retract(tau);
      minus[key] = x[key].retract(-tau);
      numeric.col(c) = (f.error(plus) - f.error(minus)) / (2 * kStep);
    }
    const Eigen::MatrixXd analytic = J[static_cast<size_t>(k)];
    EXPECT_LT((analytic - numeric).cwiseAbs().maxCoeff(), kTolerance)
        << f.name() << " key " << k << "\nanalytic\n"
        << analytic << "\nnumeric\n"
        << numeric;
  }
}

template <class G>
std::shared_ptr<const FactorModel<G>> rangeModel(const Eigen::Matrix<double, G::kDim, 1>& a,
                                                 double range) {
  return examples::RangeFactor<G>::Create({a, range}, "range");
}

template <class G>
class CustomFactorTest : public ::testing::Test {};
using Groups = ::testing::Types<SE2, SE3>;
TYPED_TEST_SUITE(CustomFactorTest, Groups);

TYPED_TEST(CustomFactorTest, RangeJacobiansMatchCentralDifferences) {
  using G = TypeParam;
  std::mt19937_64 rng(1);
  for (int trial = 0; trial < 20; ++trial) {
    const std::vector<G> x{randomPose<G>(rng)};
    const auto f = CustomFactor<G>::make(rangeModel<G>(randomPoint<G>(rng, 10), 4.0),
                                         Eigen::MatrixXd::Constant(1, 1, 9.0), 0);
    expectJacobiansMatch(f, x);
  }
}

TYPED_TEST(CustomFactorTest, RelativePositionJacobiansMatchAndAgree) {
  using G = TypeParam;
  constexpr int D = G::kDim;
  std::mt19937_64 rng(2);
  for (int trial = 0; trial < 20; ++trial) {
    const std::vector<G> x{randomPose<G>(rng), randomPose<G>(rng)};
    const Eigen::Matrix<double, D, 1> p = randomPoint<G>(rng, 3);
    const Eigen::MatrixXd omega = randomSpd<D>(rng);
    const auto autodiff = CustomFactor<G>::make(
        examples::RelativePositionAutoDiff<G>::Create({p}, "relative_position"), omega, 0, 1);
    const auto analytic = CustomFactor<G>::make(
        std::make_shared<const examples::RelativePositionFactor<G>>(p), omega, 0, 1);
    expectJacobiansMatch(autodiff, x);
    expectJacobiansMatch(analytic, x);
    typename FactorModel<G>::Jacobians Ja, Jb;
    EXPECT_LT((autodiff.error(x, &Ja) - analytic.error(x, &Jb)).cwiseAbs().maxCoeff(), 1e-12);
    for (int k = 0; k < 2; ++k) EXPECT_LT((Ja[k] - Jb[k]).cwiseAbs().maxCoeff(), 1e-12);
  }
}

TEST(CustomFactor, PlanarMotionJacobiansMatchAndAgree) {
  std::mt19937_64 rng(3);
  for (int trial = 0; trial < 20; ++trial) {
    const std::vector<SE3> x{randomPose<SE3>(rng)};
    const Eigen::MatrixXd omega = randomSpd<3>(rng);
    const auto autodiff = CustomFactor<SE3>::make(
        examples::PlanarMotionAutoDiff::Create({}, "planar_motion"), omega, 0);
    const auto analytic =
        CustomFactor<SE3>::make(std::make_shared<const examples::PlanarMotionFactor>(), omega, 0);
    expectJacobiansMatch(autodiff, x);
    expectJacobiansMatch(analytic, x);
    typename FactorModel<SE3>::Jacobians Ja, Jb;
    EXPECT_LT((autodiff.error(x, &Ja) - analytic.error(x, &Jb)).cwiseAbs().maxCoeff(), 1e-12);
    EXPECT_LT((Ja[0] - Jb[0]).cwiseAbs().maxCoeff(), 1e-12);
  }
  // Near planar: e ≈ [z; roll; pitch].
  const double z = 0.01, roll = 0.002, pitch = -0.003;
  const Eigen::Quaterniond q(Eigen::AngleAxisd(0.7, Eigen::Vector3d::UnitZ()) *
                             Eigen::AngleAxisd(pitch, Eigen::Vector3d::UnitY()) *
                             Eigen::AngleAxisd(roll, Eigen::Vector3d::UnitX()));
  const std::vector<SE3> x{SE3(q, Eigen::Vector3d(4, -2, z))};
  const auto f = CustomFactor<SE3>::make(std::make_shared<const examples::PlanarMotionFactor>(),
                                         Eigen::Matrix3d::Identity(), 0);
  const Eigen::Vector3d e = f.error(x);
  EXPECT_NEAR(e(0), z, 1e-15);
  EXPECT_NEAR(e(1), roll, 1e-7);  // cos β sin α
  EXPECT_NEAR(e(2), pitch, 1e-7);
}

// Factor<G>: the whitened linearisation zero-padded to kDoF rows, ‖r‖² = eᵀΩe = cost().
TYPED_TEST(CustomFactorTest, FactorLinearizesWhitenedAndPadded) {
  using G = TypeParam;
  std::mt19937_64 rng(4);
  const std::vector<G> x{randomPose<G>(rng), randomPose<G>(rng)};
  const Eigen::MatrixXd omega = randomSpd<G::kDim>(rng);
  const auto c = CustomFactor<G>::make(
      examples::RelativePositionAutoDiff<G>::Create({randomPoint<G>(rng, 2)}), omega, 0, 1);
  const Factor<G> f(c);
  EXPECT_EQ(f.kind(), FactorKind::kCustom);
  EXPECT_EQ(f.arity(), 2);
  EXPECT_EQ(f.key(1), 1);
  EXPECT_EQ(f.name(), "autodiff");
  EXPECT_TRUE(f.isFinite());
  typename Factor<G>::Linearization L;
  f.linearize(x, &L);
  typename FactorModel<G>::Jacobians J;
  const Eigen::VectorXd e = c.error(x, &J);
  EXPECT_NEAR(L.r.squaredNorm(), e.dot(omega * e), 1e-9 * (1 + f.cost(x)));
  EXPECT_NEAR(f.cost(x), e.dot(omega * e), 1e-12 * (1 + f.cost(x)));
  EXPECT_TRUE(L.r.tail(G::kDoF - G::kDim).isZero(0.0));
  for (int k = 0; k < 2; ++k) {
    EXPECT_TRUE(L.A[k].bottomRows(G::kDoF - G::kDim).isZero(0.0));
    const Eigen::MatrixXd H = L.A[k].transpose() * L.A[k];
    const Eigen::MatrixXd expected = J[k].transpose() * omega * J[k];
    EXPECT_LT((H - expected).cwiseAbs().maxCoeff(), 1e-9 * (1 + expected.norm()));
  }
  Factor<G> moved = f;
  moved.setKeys(3, 5);
  EXPECT_EQ(moved.key(0), 3);
  EXPECT_EQ(moved.key(1), 5);
}

/// Dense Gauss–Newton step over the poses not fixed (zero for fixed ones) for any factors, each
/// scaled by its inlier weight (linearizeWeighted), as tests/smoother_priors_test.cc's.
template <class G>
std::vector<typename G::Tangent> denseStep(const std::vector<Factor<G>>& factors,
                                           const std::vector<G>& x,
                                           const std::vector<char>& fixed = {}) {
  constexpr int D = G::kDoF;
  const int n = static_cast<int>(x.size());
  std::vector<int> col(n, -1);
  int m = 0;
  for (int k = 0; k < n; ++k)
    if (fixed.empty() || !fixed[k]) col[k] = m++;
  Eigen::MatrixXd H = Eigen::MatrixXd::Zero(m * D, m * D);
  Eigen::VectorXd b = Eigen::VectorXd::Zero(m * D);
  for (const Factor<G>& f : factors) {
    typename Factor<G>::Linearization L;
    f.linearizeWeighted(x, &L);
    for (int k = 0; k < f.arity(); ++k) {
      const int ck = col[f.key(k)];
      if (ck < 0) continue;
      b.segment<D>(ck * D) -= L.A[k].transpose() * L.r;
      for (int l = 0; l < f.arity(); ++l) {
        const int cl = col[f.key(l)];
        if (cl >= 0) H.block<D, D>(ck * D, cl * D) += L.A[k].transpose() * L.A[l];
      }
    }
  }
  const Eigen::VectorXd dx = H.llt().solve(b);
  std::vector<typename G::Tangent> out(n, G::Tangent::Zero());
  for (int k = 0; k < n; ++k)
    if (col[k] >= 0) out[k] = dx.segment<D>(col[k] * D);
  return out;
}

template <class G>
std::vector<G> trajectory(int n, std::mt19937_64& rng) {
  std::vector<G> x(n);
  for (int k = 1; k < n; ++k) {
    typename G::Tangent t = randomTangent<G>(rng, 0.2, 0.2);
    t(0) += 1.0;
    x[k] = x[k - 1].compose(G::Exp(t));
  }
  return x;
}

/// A world with custom factors: odometry edges, a pose prior on pose 0, ranges to anchors every
/// 3rd pose, relative positions as loop closures, and (3D) planar motion every 5th pose.
template <class G>
struct CustomWorld {
  std::vector<G> truth;
  std::vector<std::vector<Factor<G>>> factors_at;  // the factors that arrive with pose k
};

template <class G>
CustomWorld<G> customWorld(int n, unsigned seed, bool analytic) {
  constexpr int D = G::kDim;
  std::mt19937_64 rng(seed);
  CustomWorld<G> w;
  w.truth = trajectory<G>(n, rng);
  w.factors_at.resize(n);
  const auto noisy = [&](const G& z) { return z.compose(G::Exp(randomTangent<G>(rng, .05, .02))); };
  const auto omega = diagonalInformation<G>(100, 400);
  std::normal_distribution<double> normal(0.0, 0.1);
  w.factors_at[0].push_back(PosePriorFactor<G>::make(0, noisy(w.truth[0]), omega));
  std::vector<Eigen::Matrix<double, D, 1>> anchors;
  for (int a = 0; a < 3; ++a) anchors.push_back(randomPoint<G>(rng, 15));
  std::uniform_int_distribution<int> back(3, 10);
  for (int k = 1; k < n; ++k) {
    auto& at = w.factors_at[k];
    at.push_back(
        RelativePoseEdge<G>::make(k - 1, k, noisy(w.truth[k - 1].between(w.truth[k])), omega));
    if (k % 3 == 0) {
      const auto& a = anchors[static_cast<size_t>(k / 3 % 3)];
      const double range = (w.truth[k].translation() - a).norm() + normal(rng);
      at.push_back(
          CustomFactor<G>::make(rangeModel<G>(a, range), Eigen::MatrixXd::Constant(1, 1, 25.0), k));
    }
    if (k % 4 == 0 && k > 10) {
      const int i = k - back(rng);
      Eigen::Matrix<double, D, 1> p = w.truth[i].inverse().act(w.truth[k].translation());
      for (int c = 0; c < D; ++c) p(c) += normal(rng);
      std::shared_ptr<const FactorModel<G>> model =
          analytic ? std::shared_ptr<const FactorModel<G>>(
                         std::make_shared<const examples::RelativePositionFactor<G>>(p))
                   : examples::RelativePositionAutoDiff<G>::Create({p}, "relative_position");
      at.push_back(CustomFactor<G>::make(model, 50.0 * Eigen::MatrixXd::Identity(D, D), i, k));
    }
    if constexpr (D == 3) {
      if (k % 5 == 0) {
        std::shared_ptr<const FactorModel<G>> model =
            analytic ? std::shared_ptr<const FactorModel<G>>(
                           std::make_shared<const examples::PlanarMotionFactor>())
                     : examples::PlanarMotionAutoDiff::Create({}, "planar_motion");
        at.push_back(CustomFactor<G>::make(model, 0.5 * Eigen::MatrixXd::Identity(3, 3), k));
      }
    }
  }
  return w;
}

// The smoother's Δ after every update is one Gauss–Newton step of every factor so far, from the
// same linearisation point: the dense one and core's batch one (NormalEquations with the custom
// factors in a PoseGraph), to 1e-9.
template <class G>
void expectExactWithCustomFactors(unsigned seed, bool analytic) {
  const int n = 40;
  const CustomWorld<G> w = customWorld<G>(n, seed, analytic);
  SmootherOptions o;
  o.relinearize_threshold_translation = 0;
  o.relinearize_threshold_rotation = 0;
  o.relinearize_skip = 1;
  o.full_backsubstitution = true;
  IncrementalSmoother<G> s(o);
  std::mt19937_64 rng(seed + 100);
  s.addPose(w.truth[0].compose(G::Exp(randomTangent<G>(rng, 0.3, 0.1))));
  for (int k = 0; k < n; ++k) {
    if (k > 0) {
      const auto* odometry = w.factors_at[k][0].relativePose();
      s.addPose(s.estimate(k - 1).compose(odometry->measurement));
    }
    for (const auto& f : w.factors_at[k]) s.addFactor(f);
    s.update();
    s.checkInvariants();
    const std::vector<G>& theta = s.linearizationPoint();
    const auto dense = denseStep(s.factors(), theta);
    PoseGraph<G> graph;
    for (int v = 0; v <= k; ++v) {
      graph.ids.push_back(v);
      graph.index[v] = v;
    }
    graph.poses = theta;
    for (const auto& f : s.factors()) addToGraph(f, &graph);
    ASSERT_TRUE(graph.gaugeIndices().empty());  // the pose prior anchors it
    const auto batch = gaussNewtonStep(graph, theta);
    for (int v = 0; v <= k; ++v) {
      ASSERT_LT((s.delta()[v] - dense[v]).cwiseAbs().maxCoeff(), 1e-9)
          << "pose " << v << " after update " << k;
      ASSERT_LT((s.delta()[v] - batch[v]).cwiseAbs().maxCoeff(), 1e-9)
          << "pose " << v << " after update " << k;
    }
  }
  EXPECT_GT(s.factors().size(), static_cast<size_t>(n));
}

TEST(CustomFactorSmoother, ExactGaussNewtonStepAutoDiff2D) {
  expectExactWithCustomFactors<SE2>(5, false);
}
TEST(CustomFactorSmoother, ExactGaussNewtonStepAutoDiff3D) {
  expectExactWithCustomFactors<SE3>(6, false);
}
TEST(CustomFactorSmoother, ExactGaussNewtonStepAnalytic3D) {
  expectExactWithCustomFactors<SE3>(7, true);
}

// Batch LM and the smoother's finalize reach the same minimum of F with custom factors; the
// smoother's marginal covariance of a pose equals the dense inverse of H there.
template <class G>
void expectBatchAndSmootherAgree(unsigned seed) {
  constexpr int D = G::kDoF;
  const int n = 30;
  const CustomWorld<G> w = customWorld<G>(n, seed, false);
  SmootherOptions o;
  o.finalize_relative_tolerance = 1e-14;
  o.finalize_max_iterations = 50;
  IncrementalSmoother<G> s(o);
  PoseGraph<G> graph;
  std::vector<G> init;
  std::mt19937_64 rng(seed + 100);
  init.push_back(w.truth[0].compose(G::Exp(randomTangent<G>(rng, 0.3, 0.1))));
  s.addPose(init[0]);
  for (int k = 0; k < n; ++k) {
    if (k > 0) {
      init.push_back(init[k - 1].compose(w.factors_at[k][0].relativePose()->measurement));
      s.addPose(init[k]);
    }
    graph.ids.push_back(k);
    graph.index[k] = k;
    for (const auto& f : w.factors_at[k]) {
      s.addFactor(f);
      addToGraph(f, &graph);
    }
    s.update();
  }
  s.relinearizeAll();
  graph.poses = init;
  ASSERT_EQ(graph.numCustomFactors(),
            static_cast<int>(factorsOf(graph).size()) - graph.numEdges() - graph.numPriors());
  EXPECT_EQ(gaugeProblem(graph), "");
  std::vector<G> x = init;
  const BatchSummary summary =
      solveBatch(graph, &x, batchOptions(BatchMethod::kLevenbergMarquardt, 100, 1e-12));
  ASSERT_NE(summary.termination, Termination::kDiverged) << summary.message;
  const double F_smoother = objective(graph, s.estimate());
  EXPECT_NEAR(summary.F_final, F_smoother, 1e-6 * summary.F_final);
  for (int v = 0; v < n; ++v)
    EXPECT_LT(x[v].localCoordinates(s.estimate()[v]).cwiseAbs().maxCoeff(), 1e-5) << v;
  // Σ_v of the smoother's last linear system = the dense (H⁻¹)_vv at its linearisation point.
  std::vector<Factor<G>> fs = s.factors();
  const std::vector<G>& theta = s.linearizationPoint();
  Eigen::MatrixXd H = Eigen::MatrixXd::Zero(n * D, n * D);
  for (const auto& f : fs) {
    typename Factor<G>::Linearization L;
    f.linearize(theta, &L);
    for (int a = 0; a < f.arity(); ++a)
      for (int b = 0; b < f.arity(); ++b)
        H.block<D, D>(f.key(a) * D, f.key(b) * D) += L.A[a].transpose() * L.A[b];
  }
  const Eigen::MatrixXd cov = H.inverse();
  for (int v : {0, n / 2, n - 1}) {
    const Eigen::MatrixXd expected = cov.block<D, D>(v * D, v * D);
    EXPECT_LT((s.marginalCovariance(v) - expected).cwiseAbs().maxCoeff(),
              1e-9 * expected.cwiseAbs().maxCoeff())
        << "pose " << v;
  }
}

TEST(CustomFactorBatch, LevenbergMarquardtEqualsSmoother2D) { expectBatchAndSmootherAgree<SE2>(8); }
TEST(CustomFactorBatch, LevenbergMarquardtEqualsSmoother3D) { expectBatchAndSmootherAgree<SE3>(9); }

// The gauge: ranges at one pose fix its position, not the heading; ranges at several poses of a
// connected trajectory fix everything; a binary custom factor joins two components.
TEST(CustomFactorGauge, RangesAnchorOnlyWhenTheyFixEverything) {
  std::mt19937_64 rng(10);
  PoseGraph2 graph;
  graph.poses = trajectory<SE2>(6, rng);
  for (int k = 0; k < 6; ++k) {
    graph.ids.push_back(k);
    graph.index[k] = k;
  }
  for (int k = 1; k < 6; ++k)
    graph.edges.push_back(RelativePoseEdge<SE2>::make(
        k - 1, k, graph.poses[k - 1].between(graph.poses[k]), Eigen::Matrix3d::Identity()));
  const std::vector<Eigen::Vector2d> anchors{{10, 0}, {0, 10}, {-10, -3}};
  auto range = [&](int k, const Eigen::Vector2d& a) {
    graph.custom_factors.push_back(
        CustomFactor<SE2>::make(rangeModel<SE2>(a, (graph.poses[k].translation() - a).norm()),
                                Eigen::MatrixXd::Identity(1, 1), k));
  };
  for (const auto& a : anchors) range(2, a);
  EXPECT_EQ(graph.gaugeIndices(), std::vector<int>{0});  // rotation about pose 2 is free
  range(5, anchors[0]);
  range(5, anchors[1]);
  EXPECT_TRUE(graph.gaugeIndices().empty());
  EXPECT_EQ(gaugeProblem(graph), "");

  // Two components joined by a relative-position factor: one anchor.
  PoseGraph2 two;
  two.poses = trajectory<SE2>(4, rng);
  for (int k = 0; k < 4; ++k) {
    two.ids.push_back(k);
    two.index[k] = k;
  }
  two.edges.push_back(RelativePoseEdge<SE2>::make(0, 1, two.poses[0].between(two.poses[1]),
                                                  Eigen::Matrix3d::Identity()));
  two.edges.push_back(RelativePoseEdge<SE2>::make(2, 3, two.poses[2].between(two.poses[3]),
                                                  Eigen::Matrix3d::Identity()));
  EXPECT_EQ(two.gaugeIndices(), (std::vector<int>{0, 2}));
  const Eigen::Vector2d p = two.poses[1].inverse().act(two.poses[2].translation());
  two.custom_factors.push_back(
      CustomFactor<SE2>::make(std::make_shared<const examples::RelativePositionFactor<SE2>>(p),
                              Eigen::Matrix2d::Identity(), 1, 2));
  EXPECT_EQ(two.gaugeIndices(), std::vector<int>{0});
}

// The online layer: ranges to three beacons on a trajectory streamed edge by edge release the
// first pose's anchor once they fix the gauge, and the final estimate is batch LM's minimum of
// F over every factor; what it cannot take is refused with the reason, changing nothing.
template <class G>
void expectOnlineWithRanges(unsigned seed) {
  constexpr int D = G::kDim;
  std::mt19937_64 rng(seed);
  const int n = 30;
  const std::vector<G> truth = trajectory<G>(n, rng);  // truth[0]: the anchor's identity
  std::vector<Eigen::Matrix<double, D, 1>> beacons;
  for (int b = 0; b < 3; ++b) beacons.push_back(randomPoint<G>(rng, 10));
  std::normal_distribution<double> normal(0.0, 0.05);
  const auto omega = diagonalInformation<G>(100, 400);
  const Eigen::MatrixXd omega_range = Eigen::MatrixXd::Constant(1, 1, 400.0);
  OnlineSmoother<G> s;
  PoseGraph<G> graph;
  for (int k = 0; k < n; ++k) {
    graph.ids.push_back(k);
    graph.index[k] = k;
  }
  int ranges = 0;
  for (int k = 1; k < n; ++k) {
    const G z = truth[k - 1].between(truth[k]).compose(G::Exp(randomTangent<G>(rng, .02, .01)));
    ASSERT_EQ(s.addEdge(k - 1, k, z, omega).status, EdgeStatus::kAccepted);
    graph.edges.push_back(RelativePoseEdge<G>::make(k - 1, k, z, omega));
    if (k % 2 == 0) {
      for (const auto& b : beacons) {
        const auto model = rangeModel<G>(b, (truth[k].translation() - b).norm() + normal(rng));
        const EdgeResult r = s.addFactor(CustomFactor<G>::make(model, omega_range, 0), k);
        ASSERT_EQ(r.status, EdgeStatus::kAccepted) << r.reason;
        graph.custom_factors.push_back(CustomFactor<G>::make(model, omega_range, k));
        ++ranges;
      }
    }
    s.update();
    s.smoother().checkInvariants();
  }
  EXPECT_FALSE(s.anchorOf(0).has_value());  // the ranges fix the gauge: nothing is fixed
  EXPECT_EQ(s.stats().anchors_released, 1);
  EXPECT_EQ(s.stats().custom_accepted, ranges);
  s.finalize();
  std::vector<G> x(n);
  for (int k = 0; k < n; ++k) x[k] = s.estimate(k);
  graph.poses = x;
  EXPECT_TRUE(graph.gaugeIndices().empty());
  std::vector<G> batch = x;
  const BatchSummary summary =
      solveBatch(graph, &batch, batchOptions(BatchMethod::kLevenbergMarquardt, 100, 1e-14));
  ASSERT_NE(summary.termination, Termination::kDiverged) << summary.message;
  EXPECT_NEAR(objective(graph, x), summary.F_final, 1e-6 * summary.F_final);
  EXPECT_NEAR(s.objective(), objective(graph, x), 1e-9 * summary.F_final);

  // Refusals, each naming the factor and the reason; nothing changes.
  const auto unary = CustomFactor<G>::make(rangeModel<G>(beacons[0], 1.0), omega_range, 0);
  const Eigen::Matrix<double, D, 1> p = Eigen::Matrix<double, D, 1>::Ones();
  const auto binary =
      CustomFactor<G>::make(examples::RelativePositionAutoDiff<G>::Create({p}, "relative_position"),
                            Eigen::MatrixXd::Identity(D, D), 0, 1);
  const std::size_t factors = s.smoother().factors().size();
  EdgeResult r = s.addFactor(unary, 99);
  EXPECT_EQ(r.status, EdgeStatus::kRejected);
  EXPECT_EQ(r.reason,
            "custom factor 'range' on 99: unknown pose id 99 (an edge or a prior "
            "creates a pose, a custom factor cannot)");
  r = s.addFactor(unary, 1, 2);
  EXPECT_EQ(r.reason, "custom factor 'range' on 1, 2: a factor on 1 pose(s) given 2 ids");
  r = s.addFactor(binary, 3, 3);
  EXPECT_EQ(r.reason, "custom factor 'relative_position' on 3, 3: self-loop");
  ASSERT_EQ(s.addEdge(100, 101, G(), omega).status, EdgeStatus::kAccepted);  // a second component
  r = s.addFactor(binary, 3, 100);
  EXPECT_EQ(r.reason,
            "custom factor 'relative_position' on 3, 100: its poses are in two components; an "
            "edge must join them first");
  EXPECT_EQ(s.stats().custom_rejected, 4);
  EXPECT_EQ(s.smoother().factors().size(), factors);
  r = s.addFactor(binary, 3, 5);
  EXPECT_EQ(r.status, EdgeStatus::kAccepted) << r.reason;
}

TEST(CustomFactorOnline, RangesReleaseTheAnchorAndReachTheBatchMinimum2D) {
  expectOnlineWithRanges<SE2>(12);
}
TEST(CustomFactorOnline, RangesReleaseTheAnchorAndReachTheBatchMinimum3D) {
  expectOnlineWithRanges<SE3>(13);
}

// A robust kernel on a custom factor: ρ and w = ρ′ at eᵀΩe, √w scaling, and the smoother with
// that weight equals the weighted dense step.
TEST(CustomFactorRobust, KernelWeightsACustomFactor) {
  std::mt19937_64 rng(11);
  const std::vector<SE2> truth = trajectory<SE2>(8, rng);
  const Eigen::Vector2d anchor(3, 7);
  const double wrong = (truth[5].translation() - anchor).norm() + 3.0;  // an outlier range
  Factor2 f = CustomFactor<SE2>::make(rangeModel<SE2>(anchor, wrong),
                                      Eigen::MatrixXd::Constant(1, 1, 4.0), 5);
  f.setKernel(RobustKernel::cauchy(1.0));
  const double s = f.cost(truth);
  EXPECT_NEAR(s, 36.0, 1e-9);
  EXPECT_DOUBLE_EQ(f.robustCost(truth), RobustKernel::cauchy(1.0).rho(s));
  const double w = f.kernelWeight(truth);
  EXPECT_DOUBLE_EQ(w, RobustKernel::cauchy(1.0).weight(s));
  EXPECT_LT(w, 0.1);
  Factor2 weighted = f;
  weighted.setInlierWeight(w);
  Factor2::Linearization L, Lw;
  f.linearize(truth, &L);
  weighted.linearizeWeighted(truth, &Lw);
  EXPECT_LT((Lw.r - std::sqrt(w) * L.r).cwiseAbs().maxCoeff(), 1e-12);
  EXPECT_LT((Lw.A[0] - std::sqrt(w) * L.A[0]).cwiseAbs().maxCoeff(), 1e-12);

  IncrementalSmoother<SE2> smoother;
  smoother.addFixedPose(truth[0]);
  for (int k = 1; k < 8; ++k) {
    smoother.addPose(truth[k]);
    smoother.addFactor(RelativePoseEdge<SE2>::make(k - 1, k, truth[k - 1].between(truth[k]),
                                                   Eigen::Matrix3d::Identity()));
  }
  smoother.addFactor(f);
  smoother.update();
  const int custom = static_cast<int>(smoother.factors().size()) - 1;
  EXPECT_EQ(smoother.factors()[static_cast<size_t>(custom)].kind(), FactorKind::kCustom);
  smoother.setFactorWeight(custom, w);
  smoother.update();
  std::vector<char> fixed(8, 0);
  fixed[0] = 1;
  const auto step = denseStep(smoother.factors(), smoother.linearizationPoint(), fixed);
  for (int v = 1; v < 8; ++v)
    EXPECT_LT((smoother.delta()[v] - step[v]).cwiseAbs().maxCoeff(), 1e-9) << v;
  // The weight moved the estimate less than the unweighted factor would have.
  EXPECT_LT(smoother.factors()[static_cast<size_t>(custom)].inlierWeight(), 0.1);
}

// A model of one's own that claims more rows than kDoF.
class TooLong final : public FactorModel<SE2> {
 public:
  int rows() const override { return 4; }
  int arity() const override { return 1; }
  std::string name() const override { return "too_long"; }
  void evaluate(const std::array<const SE2*, 2>&, Residual* e, Jacobians*) const override {
    e->setZero(3);
  }
};

// A model whose error has fewer entries than it says.
class WrongSize final : public FactorModel<SE2> {
 public:
  int rows() const override { return 2; }
  int arity() const override { return 1; }
  std::string name() const override { return "wrong_size"; }
  void evaluate(const std::array<const SE2*, 2>&, Residual* e, Jacobians*) const override {
    e->setZero(1);
  }
};

template <class F>
std::string thrownBy(F&& f) {
  try {
    f();
  } catch (const std::invalid_argument& e) {
    return e.what();
  }
  return "(nothing thrown)";
}

TEST(CustomFactorInput, BadInputIsRefusedNamingTheValue) {
  const auto model = rangeModel<SE2>(Eigen::Vector2d(1, 2), 3.0);
  const Eigen::MatrixXd one = Eigen::MatrixXd::Identity(1, 1);
  const auto has = [](const std::string& message, const std::string& part) {
    return message.find(part) != std::string::npos;
  };
  const double nan = std::nan("");
  std::string m = thrownBy([&] { CustomFactor<SE2>::make(model, one * nan, 0); });
  EXPECT_TRUE(has(m, "'range'") && has(m, "information matrix") && has(m, "NaN")) << m;
  m = thrownBy([&] { CustomFactor<SE2>::make(model, -one, 0); });
  EXPECT_TRUE(has(m, "positive definite")) << m;
  m = thrownBy([&] { CustomFactor<SE2>::make(model, Eigen::MatrixXd::Identity(2, 2), 0); });
  EXPECT_TRUE(has(m, "information matrix 2x2 for a residual of 1 rows")) << m;
  m = thrownBy([&] { CustomFactor<SE2>::make(std::make_shared<const TooLong>(), one, 0); });
  EXPECT_TRUE(has(m, "'too_long'") && has(m, "residual of 4 rows, outside 1..3")) << m;
  m = thrownBy([&] { CustomFactor<SE2>::make(model, one, -2); });
  EXPECT_TRUE(has(m, "pose index -2")) << m;
  m = thrownBy([&] { CustomFactor<SE2>::make(model, one, 0, 4); });
  EXPECT_TRUE(has(m, "unary, given a second pose index 4")) << m;
  const auto binary = examples::RelativePositionAutoDiff<SE2>::Create({Eigen::Vector2d(1, 0)});
  m = thrownBy([&] { CustomFactor<SE2>::make(binary, Eigen::Matrix2d::Identity(), 3, 3); });
  EXPECT_TRUE(has(m, "second pose index 3 equals the first")) << m;
  m = thrownBy([&] { CustomFactor<SE2>::make(nullptr, one, 0); });
  EXPECT_TRUE(has(m, "no model")) << m;
  const auto wrong =
      CustomFactor<SE2>::make(std::make_shared<const WrongSize>(), Eigen::Matrix2d::Identity(), 0);
  const std::vector<SE2> x(1);
  m = thrownBy([&] { wrong.cost(x); });
  EXPECT_TRUE(has(m, "'wrong_size': error of 1 entries, expected 2")) << m;

  // Keys out of range: the smoother and the batch solver name them.
  IncrementalSmoother<SE2> s;
  s.addPose(SE2());
  m = thrownBy([&] { s.addFactor(CustomFactor<SE2>::make(model, one, 3)); });
  EXPECT_TRUE(has(m, "addFactor(range 3)") && has(m, "pose index out of range")) << m;
  PoseGraph2 graph;
  graph.ids = {7};
  graph.index[7] = 0;
  graph.poses.resize(1);
  graph.custom_factors.push_back(
      CustomFactor<SE2>::make(binary, Eigen::Matrix2d::Identity(), 0, 2));
  m = thrownBy([&] { gaugeProblem(graph); });
  EXPECT_TRUE(has(m, "custom factor 0 ('autodiff') is on pose index 2, outside 0..0")) << m;
}

// What cannot hold a custom factor says so, naming it: g2o files and the certifiable solver.
TEST(CustomFactorInput, WritersAndTheCertifiableSolverRefuse) {
  PoseGraph2 graph;
  graph.ids = {0, 1};
  graph.index = {{0, 0}, {1, 1}};
  graph.poses = {SE2(), SE2(1, 0, 0)};
  graph.edges.push_back(
      RelativePoseEdge<SE2>::make(0, 1, SE2(1, 0, 0), Eigen::Matrix3d::Identity()));
  graph.custom_factors.push_back(CustomFactor<SE2>::make(
      rangeModel<SE2>(Eigen::Vector2d(0, 5), 5.0), Eigen::MatrixXd::Identity(1, 1), 1));
  std::ostringstream out;
  std::string m = thrownBy([&] { writeG2o(out, graph, graph.poses); });
  EXPECT_NE(m.find("custom factor 0 ('range', of 1) has no g2o tag"), std::string::npos) << m;
  EXPECT_TRUE(out.str().empty());
  m = thrownBy([&] { requireRelativePoseEdgesOnly(graph); });
  EXPECT_NE(m.find("1 custom factor(s) (the first 'range')"), std::string::npos) << m;
  EXPECT_NE(m.find("--solver lm"), std::string::npos) << m;
}

}  // namespace
}  // namespace arbor
