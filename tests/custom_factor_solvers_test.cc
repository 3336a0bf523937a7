// The solvers with factors of your own (core/custom_factor.h): the incremental smoother against
// a dense and a batch Gauss–Newton step after every update (1e-9), batch LM against the
// smoother's minimum, marginal covariances, the gauge, the online layer (OnlineSmoother::
// addFactor) and a robust kernel on a custom factor.
#include <cmath>
#include <memory>
#include <random>
#include <vector>

#include <gtest/gtest.h>
#include <Eigen/Core>

#include "arbor_slam/bayestree/incremental_smoother.h"
#include "arbor_slam/bayestree/online_smoother.h"
#include "arbor_slam/core/batch_solver.h"
#include "arbor_slam/core/custom_factor.h"
#include "arbor_slam/core/example_factors.h"
#include "arbor_slam/core/factor.h"
#include "arbor_slam/core/normal_equations.h"
#include "arbor_slam/tests/custom_factor_support.h"

namespace arbor {
namespace {

using testing::denseStep;
using testing::diagonalInformation;
using testing::randomPoint;
using testing::randomTangent;
using testing::rangeModel;
using testing::trajectory;

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

}  // namespace
}  // namespace arbor
