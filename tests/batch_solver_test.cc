// Batch solvers (GN, LM, dogleg) on synthetic pose graphs with known ground truth; the sparse
// Gauss–Newton step against dense normal equations; gauge handling; singular graphs.
#include <algorithm>
#include <cmath>
#include <random>
#include <stdexcept>
#include <type_traits>

#include <gtest/gtest.h>
#include <Eigen/Dense>

#include "arbor_slam/core/batch_solver.h"
#include "arbor_slam/core/block_cholesky.h"
#include "arbor_slam/core/normal_equations.h"
#include "arbor_slam/core/pose_graph.h"
#include "arbor_slam/core/prior_factors.h"
#include "arbor_slam/core/sparse_cholesky.h"
#include "arbor_slam/tests/random_graphs.h"

namespace arbor {
namespace {

using testing::randomInformation;
using testing::randomTangent;
using testing::Synthetic;

// A random walk of n poses with odometry edges, `loops` random loop closures and one repeated
// edge; measurements exact (noise 0) or perturbed by `noise` (translation; rotation 0.3×).
// Ids are 100 + index, to tell ids from indices.
template <class G>
Synthetic<G> makeGraph(int n, int loops, double noise, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  Synthetic<G> s;
  s.truth.push_back(G::Identity());
  for (int k = 1; k < n; ++k) {
    typename G::Tangent step = randomTangent<G>(rng, 0.5, 0.3);
    step(0) += 1.0;  // mostly forward
    s.truth.push_back(s.truth.back().compose(G::Exp(step)));
  }
  auto& g = s.graph;
  for (int k = 0; k < n; ++k) {
    g.ids.push_back(100 + k);
    g.index[100 + k] = k;
  }
  const auto addEdge = [&](int i, int j) {
    G z = s.truth[i].between(s.truth[j]);
    if (noise > 0) z = z.retract(randomTangent<G>(rng, noise, 0.3 * noise));
    g.edges.push_back(RelativePoseEdge<G>::make(i, j, z, randomInformation<G>(rng)));
  };
  for (int k = 1; k < n; ++k) addEdge(k - 1, k);
  std::uniform_int_distribution<int> pick(0, n - 1);
  for (int l = 0; l < loops;) {
    const int i = pick(rng), j = pick(rng);
    if (std::abs(i - j) < 2) continue;
    addEdge(i, j);
    ++l;
  }
  addEdge(n / 2, n / 2 + 1);  // parallel to an odometry edge
  g.poses = s.truth;
  g.has_initial_estimate = true;
  return s;
}

// The truth perturbed (all but the gauge poses).
template <class G>
std::vector<G> perturbed(const Synthetic<G>& s, double translation, double rotation,
                         std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::vector<G> poses = s.truth;
  std::vector<char> fixed(poses.size(), 0);
  for (int g : s.graph.gaugeIndices()) fixed[g] = 1;
  for (size_t k = 0; k < poses.size(); ++k)
    if (!fixed[k]) poses[k] = poses[k].retract(randomTangent<G>(rng, translation, rotation));
  return poses;
}

template <class G>
double maxPoseError(const std::vector<G>& a, const std::vector<G>& b) {
  double e = 0.0;
  for (size_t k = 0; k < a.size(); ++k)
    e = std::max(e, a[k].localCoordinates(b[k]).template lpNorm<Eigen::Infinity>());
  return e;
}

const BatchMethod kMethods[] = {BatchMethod::kGaussNewton, BatchMethod::kLevenbergMarquardt,
                                BatchMethod::kDogleg};

template <class G>
class BatchSolverTest : public ::testing::Test {};
using Groups = ::testing::Types<SE2, SE3>;
TYPED_TEST_SUITE(BatchSolverTest, Groups);

TYPED_TEST(BatchSolverTest, ExactMeasurementsRecoverGroundTruth) {
  using G = TypeParam;
  const Synthetic<G> s = makeGraph<G>(60, 25, 0.0, 7);
  const std::vector<G> start = perturbed(s, 0.1, 0.05, 11);
  ASSERT_GT(objective(s.graph, start), 1.0);
  for (BatchMethod method : kMethods) {
    std::vector<G> poses = start;
    BatchOptions options;
    options.method = method;
    const BatchSummary summary = solveBatch(s.graph, &poses, options);
    EXPECT_EQ(summary.termination, Termination::kConverged)
        << toString(method) << ": " << summary.message;
    EXPECT_DOUBLE_EQ(summary.F_initial, objective(s.graph, start));
    EXPECT_LT(summary.F_final, 1e-12) << toString(method);
    EXPECT_NEAR(summary.F_final, objective(s.graph, poses), 1e-12);
    EXPECT_LT(maxPoseError(poses, s.truth), 1e-6) << toString(method);
    EXPECT_GT(summary.iterations, 0);
    EXPECT_GE(summary.time_s, 0.0);
  }
}

TYPED_TEST(BatchSolverTest, NoisyMeasurementsAllMethodsReachTheSameMinimum) {
  using G = TypeParam;
  const Synthetic<G> s = makeGraph<G>(80, 40, 0.05, 3);
  const std::vector<G> start = perturbed(s, 0.1, 0.05, 5);
  std::vector<double> finals;
  std::vector<std::vector<G>> solutions;
  for (BatchMethod method : kMethods) {
    std::vector<G> poses = start;
    BatchOptions options;
    options.method = method;
    options.relative_tolerance = 1e-12;
    options.max_iterations = 200;
    const BatchSummary summary = solveBatch(s.graph, &poses, options);
    EXPECT_EQ(summary.termination, Termination::kConverged)
        << toString(method) << ": " << summary.message;
    EXPECT_LT(summary.F_final, summary.F_initial);
    EXPECT_GT(summary.F_final, 0.0);
    EXPECT_NEAR(summary.F_final, objective(s.graph, poses), 1e-9 * summary.F_final);
    finals.push_back(summary.F_final);
    solutions.push_back(poses);
  }
  for (size_t m = 1; m < finals.size(); ++m) {
    EXPECT_NEAR(finals[m], finals[0], 1e-6 * finals[0]) << toString(kMethods[m]);
    EXPECT_LT(maxPoseError(solutions[m], solutions[0]), 1e-4) << toString(kMethods[m]);
  }
  // At the minimum the Gauss–Newton step vanishes.
  for (const auto& tau : gaussNewtonStep(s.graph, solutions[1])) EXPECT_LT(tau.norm(), 1e-5);
}

// The whitened Jacobian A (rows: edges, then pose priors, then position priors; columns: the
// non-gauge poses in pose order, var[p]) and residual r, assembled densely from each factor's
// own linearisation.
template <class G>
struct DenseSystem {
  Eigen::MatrixXd A;
  Eigen::VectorXd r;
  std::vector<int> var;  // −1 for gauge poses
};

template <class G>
DenseSystem<G> denseSystem(const PoseGraph<G>& graph, const std::vector<G>& poses) {
  constexpr int d = G::kDoF;
  const int n = graph.numPoses();
  std::vector<int> var(n, 0);
  for (int g : graph.gaugeIndices()) var[g] = -1;
  int m = 0;
  for (int p = 0; p < n; ++p)
    if (var[p] >= 0) var[p] = m++;
  // Rows: d per edge, d per pose prior, kDim per position prior.
  const int rows = d * (graph.numEdges() + static_cast<int>(graph.pose_priors.size())) +
                   G::kDim * static_cast<int>(graph.position_priors.size());
  Eigen::MatrixXd A = Eigen::MatrixXd::Zero(rows, d * m);
  Eigen::VectorXd r(rows);
  int row = 0;
  for (int k = 0; k < graph.numEdges(); ++k, row += d) {
    const auto& e = graph.edges[k];
    typename RelativePoseEdge<G>::Matrix Ai, Aj;
    typename RelativePoseEdge<G>::Vector rk;
    e.linearize(poses[e.i], poses[e.j], &Ai, &Aj, &rk);
    if (var[e.i] >= 0) A.block(row, d * var[e.i], d, d) += Ai;
    if (var[e.j] >= 0) A.block(row, d * var[e.j], d, d) += Aj;
    r.segment(row, d) = rk;
  }
  const auto addPriors = [&](const auto& priors) {
    for (const auto& p : priors) {
      using Prior = std::decay_t<decltype(p)>;
      typename Prior::Jacobian Ap;
      typename Prior::Vector rp;
      p.linearize(poses[p.i], &Ap, &rp);
      if (var[p.i] >= 0) A.template block<Prior::kRows, d>(row, d * var[p.i]) = Ap;
      r.template segment<Prior::kRows>(row) = rp;
      row += Prior::kRows;
    }
  };
  addPriors(graph.pose_priors);
  addPriors(graph.position_priors);
  return {A, r, var};
}

// H δ = −g assembled densely, with the gauge poses' rows and columns removed.
template <class G>
std::vector<typename G::Tangent> denseGaussNewtonStep(const PoseGraph<G>& graph,
                                                      const std::vector<G>& poses) {
  constexpr int d = G::kDoF;
  const int n = graph.numPoses();
  const DenseSystem<G> system = denseSystem(graph, poses);
  const Eigen::MatrixXd& A = system.A;
  const std::vector<int>& var = system.var;
  const Eigen::MatrixXd H = A.transpose() * A;
  const Eigen::VectorXd delta = H.ldlt().solve(-A.transpose() * system.r);
  std::vector<typename G::Tangent> out(n, G::Tangent::Zero());
  for (int p = 0; p < n; ++p)
    if (var[p] >= 0) out[p] = delta.segment(d * var[p], d);
  return out;
}

TYPED_TEST(BatchSolverTest, GaussNewtonStepMatchesDenseNormalEquations) {
  using G = TypeParam;
  Synthetic<G> s = makeGraph<G>(12, 6, 0.05, 21);
  // An edge from a pose to itself (its two Jacobians act on the same variable).
  std::mt19937_64 rng(23);
  s.graph.edges.push_back(RelativePoseEdge<G>::make(5, 5, G::Exp(randomTangent<G>(rng, 0.1, 0.1)),
                                                    RelativePoseEdge<G>::Matrix::Identity()));
  const std::vector<G> start = perturbed(s, 0.2, 0.1, 22);
  for (const std::vector<int>& fixed :
       {std::vector<int>{}, std::vector<int>{4}, std::vector<int>{2, 9}}) {
    s.graph.fixed = fixed;
    const auto sparse = gaussNewtonStep(s.graph, start);
    const auto dense = denseGaussNewtonStep(s.graph, start);
    ASSERT_EQ(sparse.size(), start.size());
    double largest = 0.0;
    for (size_t p = 0; p < sparse.size(); ++p) {
      EXPECT_LT((sparse[p] - dense[p]).template lpNorm<Eigen::Infinity>(), 1e-9) << "pose " << p;
      largest = std::max(largest, dense[p].norm());
    }
    EXPECT_GT(largest, 1e-2);  // the step is not trivially zero
    for (int g : s.graph.gaugeIndices()) EXPECT_EQ(sparse[g].norm(), 0.0);
  }
}

// Random information of a prior with m residual rows (dense, positive definite).
template <int m>
Eigen::Matrix<double, m, m> priorInformation(std::mt19937_64& rng) {
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  Eigen::Matrix<double, m, m> b;
  for (int k = 0; k < b.size(); ++k) b.data()[k] = u(rng);
  return b * b.transpose() + 10.0 * Eigen::Matrix<double, m, m>::Identity();
}

// The synthetic graph moved rigidly to a random world frame (the priors' frame), so that the
// first pose is not the identity.
template <class G>
void moveToWorld(Synthetic<G>* s, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  const G world = G::Exp(randomTangent<G>(rng, 5.0, 1.0));
  for (G& x : s->truth) x = world.compose(x);
  s->graph.poses = s->truth;
}

TYPED_TEST(BatchSolverTest, GaussNewtonStepWithPriorsMatchesDenseNormalEquations) {
  using G = TypeParam;
  constexpr int D = G::kDoF, d = G::kDim;
  Synthetic<G> s = makeGraph<G>(12, 6, 0.05, 24);
  std::mt19937_64 rng(25);
  auto& g = s.graph;
  g.pose_priors.push_back(PosePriorFactor<G>::make(
      3, s.truth[3].retract(randomTangent<G>(rng, 0.1, 0.1)), priorInformation<D>(rng)));
  const G offset = G::Exp(randomTangent<G>(rng, 0.5, 0.5));
  g.pose_priors.push_back(PosePriorFactor<G>::make(
      0, s.truth[0].compose(offset).retract(randomTangent<G>(rng, 0.1, 0.1)),
      priorInformation<D>(rng), offset));
  for (int k : {0, 5, 8, 8})
    g.position_priors.push_back(PositionPriorFactor<G>::make(
        k, s.truth[k].translation() + randomTangent<G>(rng, 0.1, 0).template head<d>(),
        priorInformation<d>(rng)));
  const std::vector<G> start = perturbed(s, 0.2, 0.1, 26);
  // No fixed pose (the priors anchor it), one, and two with priors on the gauge pose 0.
  for (const std::vector<int>& fixed :
       {std::vector<int>{}, std::vector<int>{4}, std::vector<int>{0, 9}}) {
    g.fixed = fixed;
    EXPECT_EQ(g.gaugeIndices(), fixed);
    EXPECT_EQ(gaugeProblem(g), "");
    const auto sparse = gaussNewtonStep(g, start);
    const auto dense = denseGaussNewtonStep(g, start);
    double largest = 0.0;
    for (size_t p = 0; p < sparse.size(); ++p) {
      EXPECT_LT((sparse[p] - dense[p]).template lpNorm<Eigen::Infinity>(), 1e-9) << "pose " << p;
      largest = std::max(largest, dense[p].norm());
    }
    EXPECT_GT(largest, 1e-2);
    for (int k : fixed) EXPECT_EQ(sparse[k].norm(), 0.0);
    // F, the model and ‖Av‖² over every factor, the gauge pose's priors as constants.
    const DenseSystem<G> system = denseSystem(g, start);
    for (CholeskyBackend backend : {CholeskyBackend::kBlock, CholeskyBackend::kCholmod}) {
      NormalEquations<G> equations(g, backend);
      const double F = objective(g, start);
      EXPECT_NEAR(equations.linearize(start), F, 1e-9 * F);
      EXPECT_NEAR(system.r.squaredNorm(), F, 1e-9 * F);
      const Eigen::VectorXd v = Eigen::VectorXd::LinSpaced(equations.dimension(), -0.2, 0.3);
      // v over the variables in the solver's order, as the dense columns (pose order).
      Eigen::VectorXd v_dense = Eigen::VectorXd::Zero(system.A.cols());
      const auto v_pose = equations.perPose(v);
      for (int p = 0; p < g.numPoses(); ++p)
        if (system.var[p] >= 0) v_dense.segment(D * system.var[p], D) = v_pose[p];
      EXPECT_NEAR(equations.modelCost(v), (system.r + system.A * v_dense).squaredNorm(), 1e-9 * F);
      EXPECT_NEAR(equations.jacobianSquaredNorm(v), (system.A * v_dense).squaredNorm(), 1e-9 * F);
      ASSERT_TRUE(equations.factorize());
      Eigen::VectorXd delta;
      equations.solve(-equations.gradient(), &delta);
      const auto step = equations.perPose(delta);
      for (size_t p = 0; p < step.size(); ++p)
        EXPECT_LT((step[p] - dense[p]).template lpNorm<Eigen::Infinity>(), 1e-9);
    }
  }
}

// Position priors on every 10th pose and no fixed pose: the priors alone fix the gauge.
TYPED_TEST(BatchSolverTest, PositionPriorsEveryTenthPoseAnchorTheGraph) {
  using G = TypeParam;
  constexpr int d = G::kDim;
  for (const double noise : {0.0, 0.05}) {
    Synthetic<G> s = makeGraph<G>(60, 20, noise, 33);
    moveToWorld(&s, 34);
    std::mt19937_64 rng(35);
    for (int k = 0; k < 60; k += 10)
      s.graph.position_priors.push_back(PositionPriorFactor<G>::make(
          k, s.truth[k].translation() + randomTangent<G>(rng, noise, 0).template head<d>(),
          priorInformation<d>(rng)));
    ASSERT_TRUE(s.graph.gaugeIndices().empty());
    std::vector<G> start = s.truth;
    for (auto& x : start) x = x.retract(randomTangent<G>(rng, 0.1, 0.05));
    std::vector<std::vector<G>> solutions;
    std::vector<double> finals;
    for (BatchMethod method : kMethods) {
      std::vector<G> poses = start;
      BatchOptions options;
      options.method = method;
      options.relative_tolerance = 1e-12;
      options.max_iterations = 200;
      const BatchSummary summary = solveBatch(s.graph, &poses, options);
      EXPECT_EQ(summary.termination, Termination::kConverged)
          << toString(method) << ": " << summary.message;
      EXPECT_DOUBLE_EQ(summary.F_initial, objective(s.graph, start));
      EXPECT_NEAR(summary.F_final, objective(s.graph, poses), 1e-9 * summary.F_initial);
      if (noise == 0.0) {
        EXPECT_LT(summary.F_final, 1e-12) << toString(method);
        EXPECT_LT(maxPoseError(poses, s.truth), 1e-6) << toString(method);
      } else {
        EXPECT_GT(summary.F_final, 0.0);
        EXPECT_LT(maxPoseError(poses, s.truth), 0.5) << toString(method);
      }
      finals.push_back(summary.F_final);
      solutions.push_back(poses);
    }
    for (size_t m = 1; m < finals.size(); ++m) {
      EXPECT_NEAR(finals[m], finals[0], 1e-6 * finals[0] + 1e-12) << toString(kMethods[m]);
      EXPECT_LT(maxPoseError(solutions[m], solutions[0]), 1e-4) << toString(kMethods[m]);
    }
    // Moving the solution rigidly raises F: the gauge is not free.
    if (noise > 0) {
      const G shift = G::Exp(randomTangent<G>(rng, 0.1, 0.05));
      std::vector<G> moved = solutions[1];
      for (auto& x : moved) x = shift.compose(x);
      EXPECT_GT(objective(s.graph, moved), finals[1] * (1 + 1e-3));
    }
  }
}

// One pose prior (with a sensor offset) and no fixed pose: with exact edges the minimum moves
// the graph rigidly onto the prior, F = 0 there.
TYPED_TEST(BatchSolverTest, PosePriorWithoutFixedPoseSolves) {
  using G = TypeParam;
  Synthetic<G> s = makeGraph<G>(40, 15, 0.0, 36);
  moveToWorld(&s, 37);
  std::mt19937_64 rng(38);
  const G offset = G::Exp(randomTangent<G>(rng, 0.3, 0.3));
  const G z = s.truth[7].compose(offset).retract(randomTangent<G>(rng, 0.2, 0.1));
  s.graph.pose_priors.push_back(
      PosePriorFactor<G>::make(7, z, priorInformation<G::kDoF>(rng), offset));
  ASSERT_TRUE(s.graph.gaugeIndices().empty());
  std::vector<G> start = s.truth;
  for (auto& x : start) x = x.retract(randomTangent<G>(rng, 0.1, 0.05));
  for (BatchMethod method : kMethods) {
    std::vector<G> poses = start;
    BatchOptions options;
    options.method = method;
    options.relative_tolerance = 1e-12;
    const BatchSummary summary = solveBatch(s.graph, &poses, options);
    EXPECT_EQ(summary.termination, Termination::kConverged)
        << toString(method) << ": " << summary.message;
    EXPECT_LT(summary.F_final, 1e-12) << toString(method);
    EXPECT_LT(poses[7].compose(offset).localCoordinates(z).norm(), 1e-6) << toString(method);
    for (int k = 1; k < 40; ++k)
      EXPECT_LT(poses[k - 1]
                    .between(poses[k])
                    .localCoordinates(s.truth[k - 1].between(s.truth[k]))
                    .norm(),
                1e-6);
  }
}

// A prior on a gauge pose is a constant of F: it shifts F and leaves the solution alone.
TYPED_TEST(BatchSolverTest, PriorOnAGaugePoseOnlyAddsAConstant) {
  using G = TypeParam;
  Synthetic<G> s = makeGraph<G>(30, 10, 0.05, 39);
  s.graph.fixed = {0};
  const std::vector<G> start = perturbed(s, 0.1, 0.05, 40);
  std::vector<G> plain = start;
  BatchOptions options;
  options.relative_tolerance = 1e-12;
  const BatchSummary without = solveBatch(s.graph, &plain, options);
  std::mt19937_64 rng(41);
  s.graph.pose_priors.push_back(PosePriorFactor<G>::make(
      0, start[0].retract(randomTangent<G>(rng, 0.5, 0.2)), priorInformation<G::kDoF>(rng)));
  s.graph.position_priors.push_back(PositionPriorFactor<G>::make(
      0, start[0].translation() + randomTangent<G>(rng, 0.5, 0).template head<G::kDim>(),
      priorInformation<G::kDim>(rng)));
  const double constant =
      s.graph.pose_priors[0].cost(start[0]) + s.graph.position_priors[0].cost(start[0]);
  ASSERT_GT(constant, 1.0);
  std::vector<G> with_priors = start;
  const BatchSummary with = solveBatch(s.graph, &with_priors, options);
  EXPECT_EQ(with.termination, Termination::kConverged) << with.message;
  EXPECT_NEAR(with.F_initial, without.F_initial + constant, 1e-9 * with.F_initial);
  EXPECT_NEAR(with.F_final, without.F_final + constant, 1e-6 * with.F_final);
  EXPECT_LT(maxPoseError(with_priors, plain), 1e-6);
}

// Both Cholesky backends of NormalEquations against dense (H + diag(damping)) δ = −g.
TYPED_TEST(BatchSolverTest, CholeskyBackendsMatchDenseSolution) {
  using G = TypeParam;
  constexpr int d = G::kDoF;
  Synthetic<G> s = makeGraph<G>(25, 12, 0.05, 81);
  s.graph.fixed = {7};
  const std::vector<G> start = perturbed(s, 0.2, 0.1, 82);
  const std::vector<typename G::Tangent> dense_step = denseGaussNewtonStep(s.graph, start);
  for (CholeskyBackend backend : {CholeskyBackend::kBlock, CholeskyBackend::kCholmod}) {
    NormalEquations<G> equations(s.graph, backend);
    ASSERT_EQ(equations.backend(), backend);
    ASSERT_EQ(equations.dimension(), d * 24);
    EXPECT_NEAR(equations.linearize(start), objective(s.graph, start),
                1e-9 * objective(s.graph, start));
    ASSERT_TRUE(equations.factorize());
    Eigen::VectorXd delta;
    equations.solve(-equations.gradient(), &delta);
    const auto step = equations.perPose(delta);
    for (size_t p = 0; p < step.size(); ++p)
      EXPECT_LT((step[p] - dense_step[p]).template lpNorm<Eigen::Infinity>(), 1e-9);
    // The linear model at the Gauss–Newton step: ‖r + Aδ‖² = F + gᵀδ (as Hδ = −g).
    EXPECT_NEAR(equations.modelCost(delta),
                equations.linearize(start) + equations.gradient().dot(delta),
                1e-9 * objective(s.graph, start));
    // Damped: (H + diag(λ)) δ = −g, checked through H δ computed from ‖A v‖².
    const Eigen::VectorXd damping = Eigen::VectorXd::LinSpaced(equations.dimension(), 0.5, 5.0);
    ASSERT_TRUE(equations.factorize(&damping));
    equations.solve(-equations.gradient(), &delta);
    // vᵀ(H + diag λ)δ = −vᵀg for v = δ: δᵀHδ = ‖Aδ‖².
    EXPECT_NEAR(equations.jacobianSquaredNorm(delta) + delta.dot(damping.cwiseProduct(delta)),
                -equations.gradient().dot(delta), 1e-9 * equations.gradient().norm());
  }
}

TYPED_TEST(BatchSolverTest, CholeskyFailureNamesThePose) {
  using G = TypeParam;
  Synthetic<G> s = makeGraph<G>(10, 3, 0.05, 91);
  s.graph.ids.push_back(777);  // a pose no edge touches: its block of H is zero
  s.graph.index[777] = 10;
  s.graph.fixed = {0};  // (without it, the loose pose would anchor itself: gaugeIndices)
  std::vector<G> poses = s.truth;
  poses.push_back(G::Identity());
  for (CholeskyBackend backend : {CholeskyBackend::kBlock, CholeskyBackend::kCholmod}) {
    NormalEquations<G> equations(s.graph, backend);
    equations.linearize(poses);
    EXPECT_FALSE(equations.factorize());
    EXPECT_NE(equations.factorizationFailure().find("pose id 777"), std::string::npos)
        << equations.factorizationFailure();
    const Eigen::VectorXd damping = Eigen::VectorXd::Constant(equations.dimension(), 1e-3);
    EXPECT_TRUE(equations.factorize(&damping));  // damping makes it definite
    EXPECT_EQ(equations.factorizationFailure(), "");
  }
}

TYPED_TEST(BatchSolverTest, GaugePosesDoNotMoveAndDoNotChangeTheMinimum) {
  using G = TypeParam;
  Synthetic<G> s = makeGraph<G>(40, 15, 0.05, 31);
  // Perturb every pose, the first included.
  std::mt19937_64 rng(32);
  std::vector<G> start = s.truth;
  for (auto& x : start) x = x.retract(randomTangent<G>(rng, 0.1, 0.05));
  double F_default = 0.0;
  for (const std::vector<int>& fixed :
       {std::vector<int>{}, std::vector<int>{17}, std::vector<int>{3, 30}}) {
    s.graph.fixed = fixed;
    for (BatchMethod method : kMethods) {
      std::vector<G> poses = start;
      BatchOptions options;
      options.method = method;
      options.relative_tolerance = 1e-12;
      const BatchSummary summary = solveBatch(s.graph, &poses, options);
      ASSERT_EQ(summary.termination, Termination::kConverged) << summary.message;
      for (int g : s.graph.gaugeIndices()) {
        EXPECT_EQ(poses[g].translation(), start[g].translation()) << "gauge pose " << g;
        EXPECT_EQ(poses[g].localCoordinates(start[g]).norm(), 0.0) << "gauge pose " << g;
      }
      // A non-gauge pose moved.
      const int other = s.graph.gaugeIndices().front() == 0 ? 1 : 0;
      EXPECT_GT(poses[other].localCoordinates(start[other]).norm(), 1e-3);
      // One fixed pose only chooses the gauge: the minimum is the same. Two perturbed fixed
      // poses also constrain their relative pose, so F can only be higher.
      if (F_default == 0.0) F_default = summary.F_final;
      if (fixed.size() <= 1) {
        EXPECT_NEAR(summary.F_final, F_default, 1e-6 * F_default) << toString(method);
      } else {
        EXPECT_GT(summary.F_final, F_default * (1 + 1e-6)) << toString(method);
      }
    }
  }
}

// Rotations perturbed by ~1 rad: Gauss–Newton may blow up (and must then hand back the best
// point it saw), LM converges (to the truth or, the problem being non-convex, a local
// minimum); nobody ends above the start.
TYPED_TEST(BatchSolverTest, LargePerturbationsNeverEndAboveTheStart) {
  using G = TypeParam;
  int gauss_newton_diverged = 0;
  for (std::uint64_t seed = 0; seed < 6; ++seed) {
    const Synthetic<G> s = makeGraph<G>(30, 15, 0.0, 100 + seed);
    const std::vector<G> start = perturbed(s, 1.0, 1.0, 200 + seed);
    for (BatchMethod method : kMethods) {
      std::vector<G> poses = start;
      BatchOptions options;
      options.method = method;
      const BatchSummary summary = solveBatch(s.graph, &poses, options);
      EXPECT_LE(summary.F_final, summary.F_initial) << toString(method) << " seed " << seed;
      EXPECT_NEAR(summary.F_final, objective(s.graph, poses), 1e-9 * summary.F_initial);
      if (method == BatchMethod::kLevenbergMarquardt) {
        EXPECT_EQ(summary.termination, Termination::kConverged) << summary.message;
        EXPECT_LT(summary.F_final, 0.5 * summary.F_initial) << "seed " << seed;
      }
      if (method == BatchMethod::kGaussNewton && summary.termination == Termination::kDiverged) {
        ++gauss_newton_diverged;
        EXPECT_NE(summary.message.find("diverged"), std::string::npos);
      }
    }
  }
  this->RecordProperty("gauss_newton_diverged", gauss_newton_diverged);
  // In 3D these starts make plain Gauss–Newton overshoot: its divergence path is exercised.
  if (std::is_same_v<G, SE3>) {
    EXPECT_GT(gauss_newton_diverged, 0);
  }
}

TYPED_TEST(BatchSolverTest, UnconstrainedPoseIsReportedNotCrashed) {
  using G = TypeParam;
  Synthetic<G> s = makeGraph<G>(20, 5, 0.05, 41);
  s.graph.ids.push_back(999);  // a pose with no edges
  s.graph.index[999] = 20;
  s.truth.push_back(G::Identity());
  // Without `fixed` the loose pose is a component of its own, anchored at itself: it stays
  // where it starts and the rest is solved.
  {
    std::vector<G> poses = perturbed(s, 0.1, 0.05, 42);
    std::mt19937_64 loose_rng(43);
    poses[20] = G::Exp(randomTangent<G>(loose_rng, 1.0, 1.0));
    const G loose = poses[20];
    EXPECT_EQ(s.graph.gaugeIndices(), (std::vector<int>{0, 20}));
    const BatchSummary summary = solveBatch(s.graph, &poses);
    EXPECT_EQ(summary.termination, Termination::kConverged) << summary.message;
    EXPECT_EQ(poses[20].localCoordinates(loose).norm(), 0.0);
  }
  s.graph.fixed = {0};  // an explicit gauge leaves the loose pose unanchored
  const std::vector<G> start = perturbed(s, 0.1, 0.05, 42);
  for (BatchMethod method : kMethods) {
    std::vector<G> poses = start;
    BatchOptions options;
    options.method = method;
    const BatchSummary summary = solveBatch(s.graph, &poses, options);
    EXPECT_EQ(summary.termination, Termination::kDiverged) << toString(method);
    EXPECT_NE(summary.message.find("pose id 999"), std::string::npos) << summary.message;
    EXPECT_EQ(maxPoseError(poses, start), 0.0);
    EXPECT_DOUBLE_EQ(summary.F_final, objective(s.graph, start));
  }
  EXPECT_THROW(gaussNewtonStep(s.graph, start), std::runtime_error);
  // Fixing the loose pose makes the problem well posed again.
  s.graph.fixed = {0, 20};
  std::vector<G> poses = start;
  EXPECT_EQ(solveBatch(s.graph, &poses).termination, Termination::kConverged);
}

TYPED_TEST(BatchSolverTest, ComponentWithoutFixedPoseIsReported) {
  using G = TypeParam;
  Synthetic<G> s = makeGraph<G>(20, 5, 0.05, 51);
  // Edges only within 0..9 and within 10..19: the second half floats.
  std::vector<RelativePoseEdge<G>> kept;
  for (const auto& e : s.graph.edges)
    if ((e.i < 10) == (e.j < 10)) kept.push_back(e);
  s.graph.edges = kept;
  // Without `fixed` each component is anchored at its first pose.
  EXPECT_EQ(s.graph.gaugeIndices(), (std::vector<int>{0, 10}));
  EXPECT_EQ(gaugeProblem(s.graph), "");
  std::vector<G> poses = perturbed(s, 0.1, 0.05, 52);
  EXPECT_EQ(solveBatch(s.graph, &poses).termination, Termination::kConverged);
  // With an explicit gauge in the first half, the second half floats.
  s.graph.fixed = {0};
  poses = perturbed(s, 0.1, 0.05, 52);
  const BatchSummary summary = solveBatch(s.graph, &poses);
  EXPECT_EQ(summary.termination, Termination::kDiverged);
  EXPECT_NE(summary.message.find("pose id 110"), std::string::npos) << summary.message;
  EXPECT_NE(summary.message.find("9 other"), std::string::npos) << summary.message;
  // One position prior leaves it free to rotate about that point (refused); priors at
  // positions that fix the rotation (2 in 2D, 3 non-collinear in 3D) anchor it.
  const auto omega = PositionPriorFactor<G>::Matrix::Identity();
  s.graph.position_priors.push_back(
      PositionPriorFactor<G>::make(12, s.truth[12].translation(), omega));
  EXPECT_NE(gaugeProblem(s.graph).find("pose id 110"), std::string::npos);
  s.graph.position_priors.push_back(
      PositionPriorFactor<G>::make(15, s.truth[15].translation(), omega));
  if (G::kDim == 3) {
    EXPECT_NE(gaugeProblem(s.graph).find("pose id 110"), std::string::npos);
    s.graph.position_priors.push_back(
        PositionPriorFactor<G>::make(19, s.truth[19].translation(), omega));
  }
  EXPECT_EQ(gaugeProblem(s.graph), "");
  poses = perturbed(s, 0.1, 0.05, 52);
  EXPECT_EQ(solveBatch(s.graph, &poses).termination, Termination::kConverged);
  // A pose prior anchors it too.
  s.graph.position_priors.clear();
  s.graph.pose_priors.push_back(
      PosePriorFactor<G>::make(17, s.truth[17], PosePriorFactor<G>::Matrix::Identity()));
  EXPECT_EQ(gaugeProblem(s.graph), "");
  // A prior on an index outside the graph is refused, naming it.
  s.graph.pose_priors.back().i = 20;
  try {
    gaugeProblem(s.graph);
    ADD_FAILURE() << "no exception";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("pose prior 0 is on pose index 20"), std::string::npos)
        << e.what();
  }
}

TYPED_TEST(BatchSolverTest, NonFiniteStartIsReported) {
  using G = TypeParam;
  const Synthetic<G> s = makeGraph<G>(10, 3, 0.05, 61);
  std::vector<G> poses = s.truth;
  typename G::Tangent bad = G::Tangent::Zero();
  bad(0) = std::numeric_limits<double>::quiet_NaN();
  poses[5] = poses[5].retract(bad);
  for (BatchMethod method : kMethods) {
    BatchOptions options;
    options.method = method;
    std::vector<G> p = poses;
    const BatchSummary summary = solveBatch(s.graph, &p, options);
    EXPECT_EQ(summary.termination, Termination::kDiverged);
    EXPECT_FALSE(summary.message.empty());
  }
}

TYPED_TEST(BatchSolverTest, IterationLimitIsReported) {
  using G = TypeParam;
  const Synthetic<G> s = makeGraph<G>(50, 20, 0.05, 71);
  const std::vector<G> start = perturbed(s, 0.3, 0.15, 72);
  for (BatchMethod method : kMethods) {
    std::vector<G> poses = start;
    BatchOptions options;
    options.method = method;
    options.max_iterations = 1;
    const BatchSummary summary = solveBatch(s.graph, &poses, options);
    EXPECT_EQ(summary.iterations, 1);
    EXPECT_EQ(summary.termination, Termination::kMaxIterations) << summary.message;
    EXPECT_LE(summary.F_final, summary.F_initial);
    EXPECT_NEAR(summary.F_final, objective(s.graph, poses), 1e-9 * summary.F_final);
  }
}

// A 3×3 tridiagonal pattern: diag(4, 4, 4) with off-diagonals 1 (positive definite), then the
// same pattern made indefinite.
TEST(SparseCholesky, FactorsSolvesAndReportsIndefiniteMatrices) {
  SymmetricPattern p;
  p.n = 3;
  p.col_ptr = {0, 1, 3, 5};
  p.row_idx = {0, 0, 1, 1, 2};
  const std::vector<int> order = fillReducingOrdering(p);
  std::vector<int> sorted = order;
  std::sort(sorted.begin(), sorted.end());
  EXPECT_EQ(sorted, (std::vector<int>{0, 1, 2}));

  SparseCholesky cholesky(p);
  const std::vector<double> indefinite = {1.0, 2.0, 1.0, 1.0, 1.0};  // [[1,2,0],[2,1,1],[0,1,1]]
  EXPECT_FALSE(cholesky.factorize(indefinite.data()));
  EXPECT_EQ(cholesky.failedColumn(), 1);
  const std::vector<double> values = {4.0, 1.0, 4.0, 1.0, 4.0};
  ASSERT_TRUE(cholesky.factorize(values.data()));
  EXPECT_EQ(cholesky.failedColumn(), -1);
  Eigen::Matrix3d dense;
  dense << 4, 1, 0, 1, 4, 1, 0, 1, 4;
  const Eigen::Vector3d b(1.0, -2.0, 3.0);
  Eigen::VectorXd x;
  cholesky.solve(b, &x);
  EXPECT_LT((x - dense.ldlt().solve(b)).norm(), 1e-12);
  EXPECT_THROW(cholesky.solve(Eigen::VectorXd::Zero(2), &x), std::invalid_argument);
  p.row_idx.pop_back();
  EXPECT_THROW(SparseCholesky bad(p), std::invalid_argument);
}

// A random sparse SPD matrix of 6×6 blocks against dense LLT.
TEST(BlockCholesky, MatchesDenseFactorisation) {
  constexpr int n = 40, d = 6;
  std::mt19937_64 rng(5);
  std::uniform_int_distribution<int> pick(0, n - 1);
  Eigen::MatrixXd a = Eigen::MatrixXd::Zero(n * d, n * d);
  std::vector<std::vector<int>> lower(n);
  for (int e = 0; e < 70; ++e) {
    const int i = pick(rng), j = pick(rng);
    if (i == j) continue;
    const Eigen::Matrix<double, d, 2 * d> jac = Eigen::Matrix<double, d, 2 * d>::Random();
    Eigen::MatrixXd h = jac.transpose() * jac;  // one "edge": PSD over poses i and j
    const int idx[2] = {i, j};
    for (int r = 0; r < 2; ++r)
      for (int c = 0; c < 2; ++c)
        a.block(idx[r] * d, idx[c] * d, d, d) += h.block(r * d, c * d, d, d);
    lower[std::min(i, j)].push_back(std::max(i, j));
  }
  a.diagonal().array() += 1.0;
  BlockCholesky<d> cholesky(lower);
  EXPECT_EQ(cholesky.numBlocks(), n);
  EXPECT_EQ(cholesky.find(3, 3), -1);  // the diagonal is not an off-diagonal block
  const auto load = [&](const Eigen::MatrixXd& m) {
    cholesky.setOffDiagonalZero();
    for (int j = 0; j < n; ++j) {
      cholesky.diagonal(j) = m.block(j * d, j * d, d, d);
      for (int i : lower[j])
        cholesky.offDiagonal(cholesky.find(i, j)) = m.block(i * d, j * d, d, d);
    }
  };
  load(a);
  ASSERT_TRUE(cholesky.factorize());
  const Eigen::VectorXd b = Eigen::VectorXd::Random(n * d);
  Eigen::VectorXd x;
  cholesky.solve(b, &x);
  EXPECT_LT((a * x - b).norm(), 1e-9 * b.norm());
  EXPECT_LT((x - a.llt().solve(b)).norm(), 1e-9 * x.norm());
  EXPECT_THROW(cholesky.solve(Eigen::VectorXd::Zero(5), &x), std::invalid_argument);
  // Indefinite: a negative eigenvalue appears in block 12's pivot.
  Eigen::MatrixXd bad = a;
  bad(12 * d + 2, 12 * d + 2) = -1e3;
  load(bad);
  EXPECT_FALSE(cholesky.factorize());
  EXPECT_EQ(cholesky.failedBlock(), 12);
  EXPECT_THROW(cholesky.solve(b, &x), std::logic_error);
  const std::vector<std::vector<int>> on_diagonal = {{0}};  // block (0, 0) is not below it
  EXPECT_THROW(BlockCholesky<d>{on_diagonal}, std::invalid_argument);
}

TEST(RelativePoseEdge, RefusesMagnitudesThatWouldOverflowF) {
  const Eigen::Matrix3d I = Eigen::Matrix3d::Identity();
  EXPECT_NO_THROW(RelativePoseEdge<SE2>::make(0, 1, SE2(kMaxTranslation, 0, 0), I));
  EXPECT_NO_THROW(RelativePoseEdge<SE2>::make(0, 1, SE2(), kMaxInformationEntry * I));
  EXPECT_THROW(RelativePoseEdge<SE2>::make(0, 1, SE2(0, -2 * kMaxTranslation, 0), I),
               std::invalid_argument);
  EXPECT_THROW(RelativePoseEdge<SE2>::make(0, 1, SE2(), 2 * kMaxInformationEntry * I),
               std::invalid_argument);
  EXPECT_EQ(translationProblem(SE3(Eigen::Quaterniond::Identity(), Eigen::Vector3d(0, 0, 1e15))),
            "");
  EXPECT_EQ(translationProblem(SE3(Eigen::Quaterniond::Identity(), Eigen::Vector3d(0, 0, 3e15))),
            "translation component of magnitude 3e+15 beyond the largest accepted (1e+15)");
  EXPECT_NE(informationProblem(Eigen::MatrixXd::Identity(6, 6) * 1e300).find("1e+300"),
            std::string::npos);
}

TEST(BatchSolver, NamesRoundTripAndBadInputIsRefused) {
  for (BatchMethod m : kMethods) EXPECT_EQ(parseBatchMethod(toString(m)), m);
  EXPECT_EQ(toString(BatchMethod::kLevenbergMarquardt), "lm");
  EXPECT_EQ(toString(Termination::kConverged), "converged");
  EXPECT_EQ(toString(Termination::kMaxIterations), "max_iterations");
  EXPECT_EQ(toString(Termination::kDiverged), "diverged");
  try {
    parseBatchMethod("newton");
    ADD_FAILURE() << "no exception";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("newton"), std::string::npos);
  }
  const Synthetic<SE2> s = makeGraph<SE2>(5, 1, 0.0, 1);
  std::vector<SE2> poses = s.truth;
  poses.pop_back();
  EXPECT_THROW(solveBatch(s.graph, &poses), std::invalid_argument);
  poses = s.truth;
  BatchOptions options;
  options.max_iterations = -1;
  EXPECT_THROW(solveBatch(s.graph, &poses, options), std::invalid_argument);
  options.max_iterations = 10;
  options.relative_tolerance = std::nan("");
  EXPECT_THROW(solveBatch(s.graph, &poses, options), std::invalid_argument);
  PoseGraph2 bad = s.graph;
  bad.fixed = {7};
  EXPECT_THROW(solveBatch(bad, &poses), std::invalid_argument);
  // At the exact solution there is nothing to do.
  const BatchSummary summary = solveBatch(s.graph, &poses);
  EXPECT_EQ(summary.termination, Termination::kConverged);
  EXPECT_EQ(summary.iterations, 0);
  EXPECT_LT(summary.F_final, 1e-20);
  // Every pose fixed: nothing to solve, F as given.
  PoseGraph2 all_fixed = s.graph;
  all_fixed.fixed = {0, 1, 2, 3, 4};
  std::vector<SE2> moved = s.truth;
  moved[2] = SE2(1.0, 2.0, 0.3);
  const BatchSummary fixed_summary = solveBatch(all_fixed, &moved);
  EXPECT_EQ(fixed_summary.termination, Termination::kConverged);
  EXPECT_EQ(fixed_summary.iterations, 0);
  EXPECT_GT(fixed_summary.F_final, 0.0);
  EXPECT_EQ(moved[2].x(), 1.0);
}

}  // namespace
}  // namespace arbor
