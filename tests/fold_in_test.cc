// The fold-in (bayestree/fold_in.h, our extension): a factor folded into the tree by rank
// updates along its path gives the same factorisation and the same solution as re-eliminating
// the whole graph with it; a factor whose ends are in different branches is refused and nothing
// changes; the split of an update keeps one introducing factor per new pose.
#include <vector>

#include <gtest/gtest.h>

#include "arbor_slam/bayestree/fold_in.h"
#include "arbor_slam/bayestree/partial_solve.h"
#include "bayes_tree_units.h"

namespace arbor {
namespace {

using testing::SmallProblem;

Eigen::VectorXd solveTree(SmallProblem* p) {
  bayestree::PartialSolve<3> solve;
  for (int v = 0; v < p->n(); ++v) solve.addVariable();
  solve.run(&p->tree, /*full=*/true, 0.0, 0.0, nullptr, &p->threads);
  Eigen::VectorXd x = Eigen::VectorXd::Zero(p->n() * 3);
  for (int v = 0; v < p->n(); ++v) x.segment<3>(v * 3) = solve.delta_newton[v];
  return x;
}

TEST(FoldIn, EqualsReeliminationWithTheFactor) {
  for (unsigned seed : {1u, 5u, 8u}) {
    SmallProblem p(25, 10, seed), q(25, 10, seed);
    p.linearizeAll();
    bayestree::TopElimination<SE2> elimination;
    p.eliminateAll(&elimination);
    // A loop closure from pose 1 to a root variable: both ends on one path to the root.
    const int root_var = p.tree.cliques[p.tree.roots[0]].frontals[0];
    const int other = root_var == 1 ? 2 : 1;
    const Factor<SE2> closure =
        RelativePoseEdge<SE2>::make(other, root_var,
                                    p.theta[other]
                                        .inverse()
                                        .compose(p.theta[root_var])
                                        .retract(Eigen::Vector3d(0.05, -0.02, 0.01)),
                                    Eigen::Matrix3d::Identity() * 30);
    const int f = p.factors.add(closure);
    p.factors.linearize(f, p.theta);
    bayestree::FoldIn<SE2> fold;
    const bayestree::FoldIn<SE2>::Context ctx{p.factors, p.theta, p.fixed, p.threads.lanes[0].slot};
    ASSERT_GE(fold.startClique(f, ctx, p.tree), 0);
    const int updated = fold.foldInAll(f, ctx, &p.tree);
    EXPECT_GE(updated, 1);
    p.tree.checkInvariants(p.factors.factors, p.factors.attached, p.fixed,
                           [](int) { return false; });
    // The same graph, closure included, eliminated from scratch.
    q.factors.add(closure);
    q.linearizeAll();
    bayestree::TopElimination<SE2> e2;
    q.eliminateAll(&e2);
    const Eigen::VectorXd x_fold = solveTree(&p), x_elim = solveTree(&q);
    EXPECT_LE((x_fold - x_elim).norm(), 1e-9 * (1 + x_elim.norm()));
    EXPECT_LE((x_fold - p.denseStep()).norm(), 1e-9 * (1 + x_elim.norm()));
    // And RᵀR is the Hessian with the closure.
    Eigen::MatrixXd H, R;
    Eigen::VectorXd g, d;
    p.denseSystem(&H, &g);
    p.treeFactor(&R, &d);
    EXPECT_LE((R.transpose() * R - H).norm(), 1e-9 * H.norm());
  }
}

TEST(FoldIn, RefusesEndsInDifferentBranches) {
  // A star: poses 1..4 each tied to the fixed pose 0 only, and a pose prior at 2: every pose is
  // a root of its own, so a factor between two of them has no path.
  SmallProblem p(5, 0, 3);
  bayestree::LinearizedFactors<SE2> star;
  for (int v = 0; v < p.n(); ++v) star.addVariable();
  for (int v = 1; v < p.n(); ++v)
    star.add(RelativePoseEdge<SE2>::make(0, v, p.theta[0].inverse().compose(p.theta[v]),
                                         Eigen::Matrix3d::Identity()));
  p.factors = star;
  p.linearizeAll();
  bayestree::TopElimination<SE2> elimination;
  p.eliminateAll(&elimination);
  ASSERT_GT(p.tree.roots.size(), 1u);
  const int f =
      p.factors.add(RelativePoseEdge<SE2>::make(1, 3, SE2(1, 0, 0), Eigen::Matrix3d::Identity()));
  p.factors.linearize(f, p.theta);
  bayestree::FoldIn<SE2> fold;
  const bayestree::FoldIn<SE2>::Context ctx{p.factors, p.theta, p.fixed, p.threads.lanes[0].slot};
  EXPECT_EQ(fold.startClique(f, ctx, p.tree), -1);
  const auto before = p.tree.cliques[p.tree.clique_of[1]].R();
  EXPECT_EQ(fold.foldInAll(f, ctx, &p.tree), -1);
  EXPECT_EQ(p.tree.cliques[p.tree.clique_of[1]].R(), before);
}

TEST(FoldIn, SplitKeepsOneIntroducingFactorPerNewPose) {
  SmallProblem p(6, 2, 4);
  p.linearizeAll();
  bayestree::TopElimination<SE2> elimination;
  p.eliminateAll(&elimination);
  // New pose 6, with two factors to the tree and a prior.
  p.theta.push_back(p.theta[5]);
  p.fixed.push_back(0);
  p.addVariable();
  std::vector<Factor<SE2>> queued = {
      RelativePoseEdge<SE2>::make(5, 6, SE2(1, 0, 0), Eigen::Matrix3d::Identity()),
      RelativePoseEdge<SE2>::make(2, 6, SE2(1, 0, 0), Eigen::Matrix3d::Identity()),
      RelativePoseEdge<SE2>::make(1, 3, SE2(1, 0, 0), Eigen::Matrix3d::Identity())};
  std::vector<int> slot(p.n(), -1);
  const auto rest = bayestree::FoldIn<SE2>::splitOffIntroducing(&queued, p.fixed, p.tree, &slot);
  ASSERT_EQ(queued.size(), 1u);  // 5–6 brings pose 6 in
  EXPECT_EQ(queued[0].key(1), 6);
  ASSERT_EQ(rest.size(), 2u);  // 1–3 (both in the tree) and 2–6 (6 joined by then)
  EXPECT_EQ(slot, std::vector<int>(p.n(), -1));
}

}  // namespace
}  // namespace arbor
