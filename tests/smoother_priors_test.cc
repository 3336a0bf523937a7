// Tests of priors and components in the smoother (bayestree/incremental_smoother.h,
// bayestree/online_smoother.h): exactness against a dense Gauss–Newton step with pose and
// position priors and no fixed pose, graphs anchored by position priors only, two robots
// streamed into one graph, the rigid move of a joining component.
#include <algorithm>
#include <cmath>
#include <random>
#include <vector>

#include <gtest/gtest.h>
#include <Eigen/Cholesky>
#include <Eigen/Core>

#include "arbor_slam/bayestree/incremental_smoother.h"
#include "arbor_slam/bayestree/online_smoother.h"
#include "arbor_slam/core/batch_solver.h"
#include "arbor_slam/core/factor.h"

namespace arbor {
namespace {

template <class G>
typename G::Tangent noise(std::mt19937& rng, double sigma_t, double sigma_r) {
  std::normal_distribution<double> n(0.0, 1.0);
  typename G::Tangent t;
  for (int k = 0; k < G::kDoF; ++k) t(k) = (k < G::kDim ? sigma_t : sigma_r) * n(rng);
  return t;
}

template <class G>
G step(std::mt19937& rng) {
  typename G::Tangent t = noise<G>(rng, 0.3, 0.3);
  t(0) += 1.0;
  return G::Exp(t);
}

template <class G>
std::vector<G> trajectory(int n, unsigned seed, const G& start = G::Identity()) {
  std::mt19937 rng(seed);
  std::vector<G> x(n, start);
  for (int k = 1; k < n; ++k) x[k] = x[k - 1].compose(step<G>(rng));
  return x;
}

template <class G>
typename RelativePoseEdge<G>::Matrix information(double t, double r) {
  typename RelativePoseEdge<G>::Matrix m = RelativePoseEdge<G>::Matrix::Zero();
  for (int k = 0; k < G::kDoF; ++k) m(k, k) = k < G::kDim ? t : r;
  return m;
}

/// Dense Gauss–Newton step over every non-fixed pose for any factors (zero for fixed poses).
template <class G>
std::vector<typename G::Tangent> denseStep(const std::vector<Factor<G>>& factors,
                                           const std::vector<G>& x,
                                           const std::vector<char>& fixed) {
  constexpr int D = G::kDoF;
  const int n = static_cast<int>(x.size());
  std::vector<int> col(n, -1);
  int m = 0;
  for (int k = 0; k < n; ++k)
    if (!fixed[k]) col[k] = m++;
  Eigen::MatrixXd H = Eigen::MatrixXd::Zero(m * D, m * D);
  Eigen::VectorXd b = Eigen::VectorXd::Zero(m * D);
  for (const Factor<G>& f : factors) {
    typename Factor<G>::Linearization L;
    f.linearize(x, &L);
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
typename G::Translation positionOf(const G& x, std::mt19937& rng, double sigma) {
  std::normal_distribution<double> n(0.0, sigma);
  typename G::Translation p = x.translation();
  for (int k = 0; k < G::kDim; ++k) p(k) += n(rng);
  return p;
}

// The exactness test of bayes_tree_test.cc with priors: no fixed pose, a pose prior on the first
// pose, position priors every 7th pose, loop closures; with β = 0 and full back-substitution the
// smoother's Δ after every update is one Gauss–Newton step of all factors so far (1e-9).
template <class G>
void expectExactWithPriors(unsigned seed) {
  std::mt19937 rng(seed);
  const int n = 40;
  const std::vector<G> truth = trajectory<G>(n, seed);
  SmootherOptions o;
  o.relinearize_threshold_translation = 0;
  o.relinearize_threshold_rotation = 0;
  o.relinearize_skip = 1;
  o.full_backsubstitution = true;
  IncrementalSmoother<G> s(o);
  const auto omega = information<G>(100, 400);
  const Eigen::Matrix<double, G::kDim, G::kDim> omega_p =
      4.0 * Eigen::Matrix<double, G::kDim, G::kDim>::Identity();
  s.addPose(truth[0].compose(G::Exp(noise<G>(rng, 0.5, 0.2))));
  s.addFactor(PosePriorFactor<G>::make(0, truth[0], omega));
  std::vector<char> fixed(1, 0);
  std::uniform_int_distribution<int> back(2, 12);
  for (int k = 1; k < n; ++k) {
    std::vector<Factor<G>> batch;
    const G z = truth[k - 1].between(truth[k]).compose(G::Exp(noise<G>(rng, 0.05, 0.02)));
    s.addPose(s.estimate(k - 1).compose(z));
    fixed.push_back(0);
    s.addFactor(RelativePoseEdge<G>::make(k - 1, k, z, omega));
    if (k % 7 == 0)
      s.addFactor(PositionPriorFactor<G>::make(k, positionOf(truth[k], rng, 0.1), omega_p));
    if (k % 3 == 0 && k > 12) {
      const int i = k - back(rng);
      s.addFactor(RelativePoseEdge<G>::make(
          i, k, truth[i].between(truth[k]).compose(G::Exp(noise<G>(rng, 0.05, 0.02))), omega));
    }
    s.update();
    s.checkInvariants();
    const auto expected = denseStep(s.factors(), s.linearizationPoint(), fixed);
    for (int v = 0; v <= k; ++v)
      ASSERT_LT((s.delta()[v] - expected[v]).cwiseAbs().maxCoeff(), 1e-9)
          << "pose " << v << " after update " << k;
  }
}

TEST(SmootherPriors, ExactGaussNewtonStepWithPriors2D) { expectExactWithPriors<SE2>(3); }
TEST(SmootherPriors, ExactGaussNewtonStepWithPriors3D) { expectExactWithPriors<SE3>(4); }

// A loop of poses anchored only by position priors every 10th pose (no fixed pose, no pose
// prior): the online layer starts anchored at the first pose and releases the anchor once the
// priors fix the gauge; the final estimate minimises F over every factor: the dense
// Gauss–Newton step there is zero and F equals batch LM's on the same problem.
template <class G>
void expectPositionPriorsAnchor(unsigned seed) {
  std::mt19937 rng(seed);
  const int n = 60;
  const G offset = G::Exp(noise<G>(rng, 20.0, 1.0));  // the world frame is not the first pose's
  const std::vector<G> truth = trajectory<G>(n, seed, offset);
  OnlineSmoother<G> s;
  const auto omega = information<G>(100, 400);
  const Eigen::Matrix<double, G::kDim, G::kDim> omega_p =
      Eigen::Matrix<double, G::kDim, G::kDim>::Identity();
  PoseGraph<G> graph;
  for (int k = 0; k < n; ++k) {
    graph.ids.push_back(k);
    graph.index[k] = k;
  }
  auto edge = [&](int i, int j) {
    const G z = truth[i].between(truth[j]).compose(G::Exp(noise<G>(rng, 0.05, 0.02)));
    ASSERT_EQ(s.addEdge(i, j, z, omega).status, EdgeStatus::kAccepted);
    graph.edges.push_back(RelativePoseEdge<G>::make(i, j, z, omega));
  };
  for (int k = 1; k < n; ++k) {
    edge(k - 1, k);
    if (k % 10 == 0) {
      const auto p = positionOf(truth[k], rng, 0.2);
      ASSERT_EQ(s.addPositionPrior(k, p, omega_p).status, EdgeStatus::kAccepted);
      graph.position_priors.push_back(PositionPriorFactor<G>::make(k, p, omega_p));
    }
    if (k == n - 1) edge(k, 0);  // closes the loop
    s.update();
    s.smoother().checkInvariants();
  }
  EXPECT_FALSE(s.anchorOf(0).has_value());  // the priors fix the gauge: nothing is fixed
  EXPECT_EQ(s.stats().anchors_released, 1);
  s.finalize();
  std::vector<G> x(n);
  for (int k = 0; k < n; ++k) x[k] = s.estimate(k);
  const std::vector<char> none(n, 0);
  const auto dx = denseStep(factorsOf(graph), x, none);
  for (int k = 0; k < n; ++k) EXPECT_LT(dx[k].cwiseAbs().maxCoeff(), 1e-4) << k;
  // Near the truth, in the world frame (not the first pose's).
  EXPECT_LT((x[n / 2].translation() - truth[n / 2].translation()).norm(), 1.0);
  const double F = objective(graph, x);
  graph.poses = x;
  for (auto& p : graph.poses) p = p.compose(G::Exp(noise<G>(rng, 0.3, 0.05)));
  std::vector<G> lm = graph.poses;
  BatchOptions tight;
  tight.relative_tolerance = 1e-12;
  tight.max_iterations = 200;
  const BatchSummary batch = solveBatch(graph, &lm, tight);
  EXPECT_NE(batch.termination, Termination::kDiverged) << batch.message;
  EXPECT_NEAR(F, batch.F_final, 1e-6 * batch.F_final);
}

TEST(SmootherPriors, PositionPriorsAloneAnchorTheGraph2D) { expectPositionPriorsAnchor<SE2>(5); }
TEST(SmootherPriors, PositionPriorsAloneAnchorTheGraph3D) { expectPositionPriorsAnchor<SE3>(6); }

// Two robots with disjoint ids, each with its own odometry, streamed interleaved; inter-robot
// loop closures arrive late. Every pose has an estimate from its first edge on; robot A (the
// older) does not jump when they join; B moves into A's frame; the final F equals batch LM's.
template <class G>
void expectTwoRobots(unsigned seed, double sigma) {
  std::mt19937 rng(seed);
  const int n = 50;
  const std::vector<G> a = trajectory<G>(n, seed);
  const std::vector<G> b = trajectory<G>(n, seed + 1, G::Exp(noise<G>(rng, 3.0, 0.5)));
  const auto omega = information<G>(100, 400);
  auto measure = [&](const G& xi, const G& xj) {
    return xi.between(xj).compose(G::Exp(noise<G>(rng, sigma, sigma / 2)));
  };
  const Key kA = 0, kB = 100000;  // robot B's ids
  OnlineSmoother<G> s;
  for (int k = 1; k < n; ++k) {
    ASSERT_EQ(s.addEdge(kA + k - 1, kA + k, measure(a[k - 1], a[k]), omega).status,
              EdgeStatus::kAccepted);
    ASSERT_EQ(s.addEdge(kB + k - 1, kB + k, measure(b[k - 1], b[k]), omega).status,
              EdgeStatus::kAccepted);
    if (k == 30 || k == 40 || k == 45) {  // inter-robot closures, late
      const int i = k - 20;
      std::vector<G> before_a(k + 1);
      for (int v = 0; v <= k; ++v) before_a[v] = s.estimate(kA + v);
      const G b_before = s.estimate(kB + i);
      const G b_truth = a[0].inverse().compose(b[i]);  // in A's frame
      ASSERT_EQ(s.addEdge(kA + i, kB + i, measure(a[i], b[i]), omega).status,
                EdgeStatus::kAccepted);
      s.update();
      s.smoother().checkInvariants();
      double a_moved = 0;
      for (int v = 0; v <= k; ++v)
        a_moved = std::max(a_moved, before_a[v].localCoordinates(s.estimate(kA + v)).norm());
      if (k == 30) {
        // The join: A stays (up to what one consistent closure corrects), B moves into A's frame.
        EXPECT_EQ(s.stats().joins, 1);
        EXPECT_EQ(s.stats().components, 1);
        EXPECT_EQ(s.anchorOf(kB), std::optional<Key>(kA));
        EXPECT_LT(a_moved, sigma > 0 ? 0.1 : 1e-9);
        EXPECT_GT(b_before.localCoordinates(s.estimate(kB + i)).norm(), 1.0);
        const double off_before = b_before.localCoordinates(b_truth).norm();
        const double off_after = s.estimate(kB + i).localCoordinates(b_truth).norm();
        if (sigma > 0)
          EXPECT_LT(off_after, 0.3 * off_before);
        else
          EXPECT_LT(off_after, 1e-6);
      }
    } else {
      s.update();
    }
    // Every pose has an estimate from its first edge on.
    ASSERT_TRUE(s.hasPose(kA + k));
    ASSERT_TRUE(s.hasPose(kB + k));
    if (k < 30) {
      EXPECT_EQ(s.stats().components, 2);
      // B is estimated in its own frame: its first pose is its anchor.
      EXPECT_EQ(s.anchorOf(kB + k), std::optional<Key>(kB));
      EXPECT_LT(s.estimate(kB + k).localCoordinates(b[0].inverse().compose(b[k])).norm(),
                sigma > 0 ? 1.0 : 1e-6);
    }
  }
  s.finalize();
  const PoseGraph<G> graph = s.snapshot();
  EXPECT_EQ(graph.fixed, std::vector<int>{0});
  std::vector<G> lm = graph.poses;
  for (size_t k = 1; k < lm.size(); ++k) lm[k] = lm[k].compose(G::Exp(noise<G>(rng, 0.1, 0.02)));
  BatchOptions tight;
  tight.relative_tolerance = 1e-12;
  tight.max_iterations = 200;
  const BatchSummary batch = solveBatch(graph, &lm, tight);
  EXPECT_NE(batch.termination, Termination::kDiverged) << batch.message;
  EXPECT_NEAR(s.smoother().objective(), batch.F_final, 1e-6 * batch.F_final + 1e-12);
}

TEST(SmootherComponents, TwoRobotsExact2D) { expectTwoRobots<SE2>(11, 0.0); }
TEST(SmootherComponents, TwoRobotsNoisy2D) { expectTwoRobots<SE2>(12, 0.02); }
TEST(SmootherComponents, TwoRobotsNoisy3D) { expectTwoRobots<SE3>(13, 0.02); }

// The rigid move leaves the Bayes tree's matrices as they were: after transformPoses of a
// component of relative-pose factors only, Δ and F are unchanged and estimates move by T.
TEST(SmootherComponents, RigidMoveKeepsDeltaAndCost) {
  std::mt19937 rng(21);
  const std::vector<SE3> x = trajectory<SE3>(20, 21);
  IncrementalSmoother<SE3> s;
  s.addFixedPose(x[0]);
  for (int k = 1; k < 20; ++k) {
    s.addPose(x[k].compose(SE3::Exp(noise<SE3>(rng, 0.1, 0.05))));
    s.addFactor(
        RelativePoseEdge<SE3>::make(k - 1, k, x[k - 1].between(x[k]), information<SE3>(10, 10)));
  }
  s.addFactor(RelativePoseEdge<SE3>::make(
      3, 17, x[3].between(x[17]).compose(SE3::Exp(noise<SE3>(rng, 0.1, 0.1))),
      information<SE3>(10, 10)));
  s.update();
  const auto delta = s.delta();
  const double F = s.objective();
  std::vector<SE3> before = s.estimate();
  std::vector<int> all(20);
  for (int k = 0; k < 20; ++k) all[k] = k;
  const SE3 T = SE3::Exp(noise<SE3>(rng, 5.0, 1.0));
  s.transformPoses(all, T);
  EXPECT_NEAR(s.objective(), F, 1e-9 * F);
  for (int k = 0; k < 20; ++k) {
    EXPECT_LT((s.delta()[k] - delta[k]).norm(), 1e-15);
    EXPECT_LT(s.estimate(k).localCoordinates(T.compose(before[k])).norm(), 1e-9);
  }
  const UpdateStats st = s.update();  // nothing to re-eliminate
  EXPECT_EQ(st.cliques_reeliminated, 0);
  s.checkInvariants();
  EXPECT_THROW(s.releaseFixedPose(5), std::invalid_argument);
}

}  // namespace
}  // namespace arbor
