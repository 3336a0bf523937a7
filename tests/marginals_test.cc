// Marginal covariances from the Bayes tree (bayestree/marginals.h, IncrementalSmoother's and
// OnlineSmoother's marginalCovariance / jointMarginalCovariance) against the dense inverse of the
// information matrix assembled from the factors' linearisations at θ.
#include <algorithm>
#include <cmath>
#include <random>
#include <stdexcept>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <Eigen/Cholesky>
#include <Eigen/Core>

#include "arbor_slam/bayestree/incremental_smoother.h"
#include "arbor_slam/bayestree/marginals.h"
#include "arbor_slam/bayestree/online_smoother.h"
#include "arbor_slam/bayestree/top_elimination.h"
#include "arbor_slam/core/factor.h"
#include "arbor_slam/core/robust_kernel.h"
#include "bayes_tree_units.h"
#include "random_graphs.h"

namespace arbor {
namespace {

using testing::randomInformation;
using testing::randomTangent;

double relativeError(const Eigen::MatrixXd& got, const Eigen::MatrixXd& want) {
  return (got - want).norm() / want.norm();
}

// ---- The unit, on a whole-graph elimination -----------------------------------------------

// Eliminates the whole of p into its tree and returns H⁻¹ of its dense system.
Eigen::MatrixXd eliminateAndInvert(testing::SmallProblem* p) {
  p->linearizeAll();
  bayestree::TopElimination<SE2> elimination;
  p->eliminateAll(&elimination);
  Eigen::MatrixXd H;
  Eigen::VectorXd g;
  p->denseSystem(&H, &g);
  return H.ldlt().solve(Eigen::MatrixXd::Identity(H.rows(), H.cols()));
}

// [[Σ_aa, Σ_ab], [Σ_ba, Σ_bb]] of variables a and b (D each) from the dense Σ.
template <int D>
Eigen::MatrixXd denseJoint(const Eigen::MatrixXd& Sigma, int a, int b) {
  Eigen::MatrixXd joint(2 * D, 2 * D);
  joint << Sigma.block<D, D>(a * D, a * D), Sigma.block<D, D>(a * D, b * D),
      Sigma.block<D, D>(b * D, a * D), Sigma.block<D, D>(b * D, b * D);
  return joint;
}

TEST(TreeMarginals, EveryMarginalAndJointMatchTheDenseInverse) {
  constexpr int D = 3;
  int cross_branch = 0, same_clique = 0, ancestor = 0;
  for (unsigned seed = 1; seed <= 6; ++seed) {
    testing::SmallProblem p(18, 5, seed);
    const Eigen::MatrixXd Sigma = eliminateAndInvert(&p);
    bayestree::TreeMarginals<D> marginals;
    const std::vector<int> vars = p.variables();
    for (int v : vars) {
      const Eigen::MatrixXd want = Sigma.block<D, D>(v * D, v * D);
      EXPECT_LT(relativeError(marginals.marginal(p.tree, v), want), 1e-8)
          << "seed " << seed << " pose " << v;
    }
    for (int a : vars)
      for (int b : vars) {
        const int ca = p.tree.clique_of[a], cb = p.tree.clique_of[b];
        if (ca == cb)
          ++same_clique;
        else if (p.tree.isAncestorOrSelf(ca, cb) || p.tree.isAncestorOrSelf(cb, ca))
          ++ancestor;
        else
          ++cross_branch;
        EXPECT_LT(relativeError(marginals.joint(p.tree, a, b), denseJoint<D>(Sigma, a, b)), 1e-8)
            << "seed " << seed << " poses " << a << ", " << b;
      }
  }
  EXPECT_GT(cross_branch, 0);  // poses in different branches were compared
  EXPECT_GT(ancestor, 0);
  EXPECT_GT(same_clique, 0);
}

// predicted(): A Σ Aᵀ by the forward substitution equals the dense one for a map A of D rows
// (a closure's: the unrolled kernels) and of 1, 2 and 5 rows (the general ones), on two, three
// and one variables, in one clique or on different branches.
TEST(TreeMarginals, PredictedMatchesTheDenseProductForEveryRowCount) {
  constexpr int D = 3;
  std::mt19937 rng(11);
  std::normal_distribution<double> normal;
  for (unsigned seed = 1; seed <= 4; ++seed) {
    testing::SmallProblem p(18, 5, seed);
    const Eigen::MatrixXd Sigma = eliminateAndInvert(&p);
    const std::vector<int> vars = p.variables();
    ASSERT_GE(vars.size(), 3u);
    const std::vector<std::vector<int>> on = {
        {vars.front(), vars.back()}, {vars[1], vars[vars.size() / 2], vars.back()}, {vars[2]}};
    for (const int m : {D, 1, 2, 5})
      for (const std::vector<int>& which : on) {
        std::vector<Eigen::MatrixXd> blocks;
        Eigen::MatrixXd A = Eigen::MatrixXd::Zero(m, Sigma.cols());
        for (const int v : which) {
          blocks.push_back(Eigen::MatrixXd::NullaryExpr(m, D, [&] { return normal(rng); }));
          A.middleCols(v * D, D) += blocks.back();
        }
        const Eigen::MatrixXd want = A * Sigma * A.transpose();
        const Eigen::MatrixXd got = bayestree::TreeMarginals<D>::predicted(p.tree, which, blocks);
        ASSERT_EQ(got.rows(), m);
        EXPECT_LT(relativeError(got, want), 1e-8)
            << "seed " << seed << ", " << m << " rows, " << which.size() << " variables";
      }
  }
}

// keepSharedCliqueJoints: every pair whose variables share a clique (the two poses of every
// factor among them) is read off one walk down the tree, jointKept then returns it (in either
// order) equal to the dense inverse, and every other pair still gets its path solves.
TEST(TreeMarginals, SharedCliqueJointsMatchTheDenseInverse) {
  constexpr int D = 3;
  for (unsigned seed = 1; seed <= 6; ++seed) {
    testing::SmallProblem p(18, 5, seed);
    const Eigen::MatrixXd Sigma = eliminateAndInvert(&p);
    const std::vector<int> vars = p.variables();
    auto holds = [&](int c, int v) {
      const auto& k = p.tree.cliques[c];
      return std::count(k.frontals.begin(), k.frontals.end(), v) +
                 std::count(k.separator.begin(), k.separator.end(), v) >
             0;
    };
    std::vector<std::pair<int, int>> pairs;
    int sharing = 0;
    for (int a : vars)
      for (int b : vars) {
        if (a >= b) continue;
        pairs.emplace_back(a, b);
        if (holds(p.tree.clique_of[a], b) || holds(p.tree.clique_of[b], a)) ++sharing;
      }
    int edges_between_variables = 0;
    for (int f = 0; f < p.factors.numFactors(); ++f)
      if (const auto* e = p.factors.factors[f].relativePose(); e && !p.fixed[e->i]) {
        ++edges_between_variables;
        EXPECT_TRUE(holds(p.tree.clique_of[e->i], e->j) || holds(p.tree.clique_of[e->j], e->i))
            << "seed " << seed << " factor " << f;
      }
    ASSERT_GT(edges_between_variables, 0);
    bayestree::TreeMarginals<D> marginals;
    EXPECT_EQ(marginals.keepSharedCliqueJoints(p.tree, pairs), sharing) << "seed " << seed;
    EXPECT_LT(sharing, static_cast<int>(pairs.size()));  // some are left to the path solves
    for (const auto& [a, b] : pairs)
      for (const auto& [x, y] : {std::pair{a, b}, std::pair{b, a}}) {
        EXPECT_LT(relativeError(marginals.jointKept(p.tree, x, y), denseJoint<D>(Sigma, x, y)),
                  1e-8)
            << "seed " << seed << " poses " << x << ", " << y;
      }
    marginals.forget();  // and again, from nothing kept
    EXPECT_EQ(marginals.keepSharedCliqueJoints(p.tree, pairs), sharing);
  }
}

// With lanes, keepSharedCliqueJoints walks independent subtrees side by side; each clique's
// joint is the same computation from its parent's, so what it keeps is the serial walk's bit
// for bit (a tree of enough cliques that the walk is shared among the lanes).
TEST(TreeMarginals, SharedCliqueJointsOnLanesEqualTheSerialWalk) {
  constexpr int D = 3;
  for (unsigned seed = 1; seed <= 3; ++seed) {
    testing::SmallProblem p(300, 40, seed);
    p.linearizeAll();
    bayestree::TopElimination<SE2> elimination;
    p.eliminateAll(&elimination);
    int cliques = 0;
    for (const auto& c : p.tree.cliques) cliques += c.in_use ? 1 : 0;
    ASSERT_GE(cliques, 64) << "seed " << seed;  // enough for the walk to be shared
    std::vector<std::pair<int, int>> pairs;
    for (int f = 0; f < p.factors.numFactors(); ++f)
      if (const auto* e = p.factors.factors[f].relativePose(); e && !p.fixed[e->i])
        pairs.emplace_back(e->i, e->j);
    bayestree::TreeMarginals<D> serial, on_lanes;
    bayestree::WorkLanes lanes(2);
    const int kept = serial.keepSharedCliqueJoints(p.tree, pairs);
    EXPECT_EQ(on_lanes.keepSharedCliqueJoints(p.tree, pairs, &lanes), kept);
    EXPECT_GT(kept, static_cast<int>(pairs.size()) / 2);
    for (const auto& [a, b] : pairs)
      EXPECT_EQ(on_lanes.jointKept(p.tree, a, b), serial.jointKept(p.tree, a, b))
          << "seed " << seed << " poses " << a << ", " << b;
    for (int v : p.variables())
      EXPECT_EQ(on_lanes.marginalKept(p.tree, v), serial.marginalKept(p.tree, v))
          << "seed " << seed << " pose " << v;
  }
}

// ---- The smoother, fed incrementally --------------------------------------------------------

/// A random graph of `n` poses per component: a chain with random loop closures, optionally a
/// pose prior and a position prior per component (then nothing is fixed) and `components`
/// disjoint components.
template <class G>
struct RandomGraph {
  int n_total = 0;
  std::vector<G> truth;
  std::vector<char> fixed;
  std::vector<Factor<G>> factors;
};

template <class G>
RandomGraph<G> randomGraph(unsigned seed, int n, int closures, bool priors, int components) {
  std::mt19937_64 rng(seed);
  RandomGraph<G> g;
  for (int c = 0; c < components; ++c) {
    const int first = g.n_total;
    for (int k = 0; k < n; ++k) {
      typename G::Tangent step = randomTangent<G>(rng, 0.5, 0.3);
      step(0) += 1.0;
      g.truth.push_back(k == 0 ? G::Exp(randomTangent<G>(rng, 5.0, 1.0))
                               : g.truth.back().compose(G::Exp(step)));
      g.fixed.push_back(k == 0 && !priors);
    }
    g.n_total += n;
    auto measured = [&](int i, int j) {
      return g.truth[i]
          .inverse()
          .compose(g.truth[j])
          .compose(G::Exp(randomTangent<G>(rng, 0.02, 0.01)));
    };
    for (int k = 1; k < n; ++k)
      g.factors.emplace_back(RelativePoseEdge<G>::make(
          first + k - 1, first + k, measured(first + k - 1, first + k), randomInformation<G>(rng)));
    std::uniform_int_distribution<int> pick(0, n - 1);
    for (int k = 0; k < closures; ++k) {
      const int i = pick(rng), j = pick(rng);
      if (std::abs(i - j) < 2) continue;
      const int a = first + std::min(i, j), b = first + std::max(i, j);
      g.factors.emplace_back(
          RelativePoseEdge<G>::make(a, b, measured(a, b), randomInformation<G>(rng)));
    }
    if (priors) {
      g.factors.emplace_back(PosePriorFactor<G>::make(first + n / 3, g.truth[first + n / 3],
                                                      randomInformation<G>(rng)));
      typename PositionPriorFactor<G>::Matrix omega =
          PositionPriorFactor<G>::Matrix::Identity() * 4.0;
      g.factors.emplace_back(
          PositionPriorFactor<G>::make(first + n - 1, g.truth[first + n - 1].translation(), omega));
    }
  }
  return g;
}

/// Fed one pose at a time (its factors to earlier poses with it), an update each: the tree
/// is built by re-eliminations, fold-ins and relinearisations (every update, β 0.01).
template <class G>
IncrementalSmoother<G> feed(const RandomGraph<G>& g) {
  SmootherOptions o;
  o.relinearize_skip = 1;
  o.relinearize_threshold_rotation = o.relinearize_threshold_translation = 0.01;
  o.threads = 1;
  IncrementalSmoother<G> s(o);
  std::mt19937_64 rng(7);
  for (int v = 0; v < g.n_total; ++v) {
    const G start = g.truth[v].retract(randomTangent<G>(rng, 0.05, 0.02));
    if (g.fixed[v])
      s.addFixedPose(g.truth[v]);
    else
      s.addPose(start);
    for (const Factor<G>& e : g.factors) {
      int last = e.key(0);
      if (e.arity() == 2) last = std::max(last, e.key(1));
      if (last == v) s.addFactor(e);
    }
    s.update();
  }
  return s;
}

/// Σ = H⁻¹, H = Σ AᵀA over the factors' weighted linearisations at θ (fixed poses: identity
/// rows, uncoupled).
template <class G>
Eigen::MatrixXd denseCovariance(const IncrementalSmoother<G>& s) {
  constexpr int D = G::kDoF;
  const int n = s.numPoses();
  Eigen::MatrixXd H = Eigen::MatrixXd::Zero(n * D, n * D);
  for (const Factor<G>& e : s.factors()) {
    typename Factor<G>::Linearization A;
    e.linearizeWeighted(s.linearizationPoint(), &A);
    for (int k = 0; k < e.arity(); ++k)
      for (int l = 0; l < e.arity(); ++l)
        if (!s.isFixed(e.key(k)) && !s.isFixed(e.key(l)))
          H.block<D, D>(e.key(k) * D, e.key(l) * D) += A.A[k].transpose() * A.A[l];
  }
  for (int v = 0; v < n; ++v)
    if (s.isFixed(v)) H.block<D, D>(v * D, v * D).setIdentity();
  Eigen::MatrixXd Sigma = H.ldlt().solve(Eigen::MatrixXd::Identity(n * D, n * D));
  for (int v = 0; v < n; ++v)
    if (s.isFixed(v)) Sigma.block<D, D>(v * D, v * D).setZero();
  return Sigma;
}

/// Every marginal and every joint (fixed poses included: zero) within 1e-8 relative.
template <class G>
void expectMatchesDense(const IncrementalSmoother<G>& s, const std::string& what) {
  constexpr int D = G::kDoF;
  const Eigen::MatrixXd Sigma = denseCovariance(s);
  const int n = s.numPoses();
  const auto all = s.marginalCovariances();  // the walk down the whole tree
  ASSERT_EQ(static_cast<int>(all.size()), n);
  for (int a = 0; a < n; ++a) {
    const Eigen::MatrixXd m = s.marginalCovariance(a);
    if (s.isFixed(a)) {
      EXPECT_EQ(m.norm(), 0.0) << what << ": fixed pose " << a;
      EXPECT_EQ(all[a].norm(), 0.0) << what << ": fixed pose " << a;
      continue;
    }
    EXPECT_LT(relativeError(m, Sigma.block<D, D>(a * D, a * D)), 1e-8) << what << " pose " << a;
    EXPECT_LT(relativeError(all[a], Sigma.block<D, D>(a * D, a * D)), 1e-8)
        << what << " pose " << a;
    // Symmetric positive definite.
    EXPECT_LT((m - m.transpose()).norm(), 1e-12 * m.norm()) << what << " pose " << a;
    EXPECT_GT(m.ldlt().vectorD().minCoeff(), 0) << what << " pose " << a;
  }
  for (int a = 0; a < n; ++a)
    for (int b = 0; b < n; ++b) {
      const Eigen::MatrixXd want = denseJoint<D>(Sigma, a, b);
      const Eigen::MatrixXd got = s.jointMarginalCovariance(a, b);
      if (want.norm() == 0) {
        EXPECT_EQ(got.norm(), 0.0) << what << " poses " << a << ", " << b;
        continue;
      }
      EXPECT_LT(relativeError(got, want), 1e-8) << what << " poses " << a << ", " << b;
    }
}

template <class G>
class SmootherMarginals : public ::testing::Test {};
using Groups = ::testing::Types<SE2, SE3>;
TYPED_TEST_SUITE(SmootherMarginals, Groups);

TYPED_TEST(SmootherMarginals, AnchoredGraphsMatchTheDenseInverse) {
  for (unsigned seed = 1; seed <= 4; ++seed) {
    const auto g = randomGraph<TypeParam>(seed, 14, 6, false, 1);
    expectMatchesDense(feed(g), "anchored, seed " + std::to_string(seed));
  }
}

TYPED_TEST(SmootherMarginals, GraphsAnchoredByPriorsMatchTheDenseInverse) {
  for (unsigned seed = 11; seed <= 13; ++seed) {
    const auto g = randomGraph<TypeParam>(seed, 12, 5, true, 1);
    expectMatchesDense(feed(g), "priors, seed " + std::to_string(seed));
  }
}

TYPED_TEST(SmootherMarginals, SeveralComponentsAreIndependent) {
  constexpr int D = TypeParam::kDoF;
  const auto g = randomGraph<TypeParam>(21, 9, 4, false, 3);
  const IncrementalSmoother<TypeParam> s = feed(g);
  expectMatchesDense(s, "three components");
  // Poses of different components: zero cross-covariance, non-zero within one.
  const auto cross = [&](int a, int b) {
    return s.jointMarginalCovariance(a, b).template topRightCorner<D, D>().norm();
  };
  EXPECT_EQ(cross(3, 9 + 5), 0.0);
  EXPECT_GT(cross(3, 5), 0.0);
}

TYPED_TEST(SmootherMarginals, AnswersFollowTheTree) {
  // Queried, then a loop closure folded in: the next queries are of the new system.
  using G = TypeParam;
  const auto g = randomGraph<G>(31, 14, 6, false, 1);
  IncrementalSmoother<G> s = feed(g);
  const Eigen::MatrixXd before = s.marginalCovariance(12);
  expectMatchesDense(s, "before the closure");
  std::mt19937_64 rng(8);
  s.addFactor(RelativePoseEdge<G>::make(1, 12, g.truth[1].inverse().compose(g.truth[12]),
                                        randomInformation<G>(rng)));
  const UpdateStats st = s.update();
  EXPECT_GT(st.cliques_updated + st.cliques_reeliminated, 0);
  expectMatchesDense(s, "after the closure");
  EXPECT_GT((before - s.marginalCovariance(12)).norm(), 1e-6 * before.norm());
  // A copy answers alike (with its own scratch).
  const IncrementalSmoother<G> copy = s;
  EXPECT_EQ(copy.jointMarginalCovariance(2, 9), s.jointMarginalCovariance(2, 9));
}

TYPED_TEST(SmootherMarginals, BadIndicesAreClearErrors) {
  const auto g = randomGraph<TypeParam>(41, 6, 0, false, 1);
  IncrementalSmoother<TypeParam> s = feed(g);
  EXPECT_THROW(s.marginalCovariance(-1), std::out_of_range);
  EXPECT_THROW(s.jointMarginalCovariance(0, 6), std::out_of_range);
  const int queued = s.addPose(TypeParam::Identity());
  try {
    s.marginalCovariance(queued);
    FAIL() << "a pose not yet through update() has no covariance";
  } catch (const std::out_of_range&) {
    FAIL() << "not out of range";
  } catch (const std::logic_error& e) {
    EXPECT_NE(std::string(e.what()).find("pose index 6: not in the Bayes tree yet"),
              std::string::npos)
        << e.what();
  }
  EXPECT_EQ(s.marginalCovariance(0).norm(), 0.0);  // the anchor
}

// ---- The online layer ---------------------------------------------------------------------

TEST(OnlineMarginals, ByIdWithComponentsAndAnchors) {
  std::mt19937_64 rng(5);
  OnlineSmoother2 s;
  const auto omega = randomInformation<SE2>(rng);
  const SE2 step(1.0, 0.1, 0.05);
  for (Key k = 100; k < 108; ++k) s.addEdge(k, k + 1, step, omega);
  s.addEdge(100, 105, step.compose(step).compose(step).compose(step).compose(step), omega);
  for (Key k = 500; k < 504; ++k) s.addEdge(k, k + 1, step, omega);  // a second component
  s.update();
  const IncrementalSmoother2& inner = s.smoother();
  const int i103 = [&] {
    for (size_t k = 0; k < s.ids().size(); ++k)
      if (s.ids()[k] == 103) return static_cast<int>(k);
    return -1;
  }();
  EXPECT_EQ(s.marginalCovariance(103), inner.marginalCovariance(i103));
  EXPECT_EQ(s.marginalCovariance(100).norm(), 0.0);  // the first component's anchor
  EXPECT_EQ(s.marginalCovariance(500).norm(), 0.0);  // the second's
  EXPECT_GT(s.marginalCovariance(504).norm(), 0.0);
  const auto cross = [&](Key a, Key b) {
    return s.jointMarginalCovariance(a, b).topRightCorner<3, 3>().norm();
  };
  EXPECT_EQ(cross(103, 503), 0.0);
  EXPECT_GT(cross(103, 107), 0.0);
  EXPECT_THROW(s.marginalCovariance(999), std::out_of_range);
  s.addEdge(108, 109, step, omega);  // 109 is known, not yet updated
  try {
    s.jointMarginalCovariance(103, 109);
    FAIL() << "109 has not been through update()";
  } catch (const std::out_of_range&) {
    FAIL() << "109 is known";
  } catch (const std::logic_error& e) {
    EXPECT_NE(std::string(e.what()).find("pose id 109"), std::string::npos) << e.what();
  }
}

// ---- A Mahalanobis gate on candidate loop closures ------------------------------------------

/// d² = rᵀ (A Σ Aᵀ + I)⁻¹ r of a candidate edge a → b, r and A = [A_a A_b] its whitened residual
/// and Jacobians at the estimate, Σ the joint covariance of a and b (`joint`: with Σ_ab, else
/// treating a and b as independent).
template <class G>
double gate(const IncrementalSmoother<G>& s, const RelativePoseEdge<G>& e, bool joint) {
  constexpr int D = G::kDoF;
  Eigen::Matrix<double, D, D> Ai, Aj;
  Eigen::Matrix<double, D, 1> r;
  e.linearize(s.estimate(e.i), s.estimate(e.j), &Ai, &Aj, &r);
  Eigen::Matrix<double, D, 2 * D> A;
  A << Ai, Aj;
  Eigen::Matrix<double, 2 * D, 2 * D> Sigma = s.jointMarginalCovariance(e.i, e.j);
  if (!joint) {
    Sigma.template topRightCorner<D, D>().setZero();
    Sigma.template bottomLeftCorner<D, D>().setZero();
  }
  const Eigen::Matrix<double, D, D> S =
      A * Sigma * A.transpose() + Eigen::Matrix<double, D, D>::Identity();
  return r.dot(S.ldlt().solve(r));
}

TEST(MarginalsGate, AcceptsTheTrueClosureAndRejectsAWrongOne) {
  const auto g = randomGraph<SE2>(51, 30, 8, false, 1);
  IncrementalSmoother2 s = feed(g);
  s.relinearizeAll();
  std::mt19937_64 rng(3);
  const int a = 4, b = 26;
  const typename RelativePoseEdge<SE2>::Matrix omega = randomInformation<SE2>(rng);
  const SE2 z_true = g.truth[a].inverse().compose(g.truth[b]);
  const SE2 z_wrong = z_true.compose(SE2(1.5, -1.0, 0.3));
  const auto good = RelativePoseEdge<SE2>::make(a, b, z_true, omega);
  const auto bad = RelativePoseEdge<SE2>::make(a, b, z_wrong, omega);
  const double threshold = chiSquareThreshold(0.99, SE2::kDoF);
  EXPECT_LT(gate(s, good, true), threshold);
  EXPECT_GT(gate(s, bad, true), threshold);
  // The cross-covariance matters: poses linked by the graph are positively correlated, so
  // treating them as independent inflates the predicted covariance and shrinks d².
  EXPECT_GT(gate(s, bad, true), gate(s, bad, false));
}

}  // namespace
}  // namespace arbor
