// The partial state update (bayestree/partial_solve.h, IJRR 2012 Alg. 7): a full solve equals
// the dense Gauss–Newton step; with a wildfire threshold α the cliques below separators that did
// not move by α are skipped, and with α = 0 every clique below a changed one is solved.
#include <algorithm>
#include <vector>

#include <gtest/gtest.h>

#include "arbor_slam/bayestree/partial_solve.h"
#include "bayes_tree_units.h"

namespace arbor {
namespace {

using testing::SmallProblem;

struct Solved {
  SmallProblem p;
  bayestree::PartialSolve<3> solve;
  std::vector<Eigen::Vector3d> delta;
  explicit Solved(int lanes = 1) : p(40, 20, 6, lanes) {
    p.linearizeAll();
    bayestree::TopElimination<SE2> elimination;
    p.eliminateAll(&elimination);
    for (int v = 0; v < p.n(); ++v) solve.addVariable();
    delta.assign(p.n(), Eigen::Vector3d::Zero());
  }
};

TEST(PartialSolve, FullSolveEqualsTheDenseStep) {
  for (int lanes : {1, 3}) {
    Solved s(lanes);
    const auto out = s.solve.run(&s.p.tree, /*full=*/true, 0.001, 0.0, &s.delta, &s.p.threads);
    EXPECT_EQ(out.solved, s.p.tree.num_cliques);
    const Eigen::VectorXd x = s.p.denseStep();
    for (int v = 0; v < s.p.n(); ++v) {
      EXPECT_LE((s.solve.delta_newton[v] - x.segment<3>(v * 3)).norm(), 1e-9 * (1 + x.norm())) << v;
      EXPECT_EQ(s.delta[v], s.solve.delta_newton[v]);
    }
  }
}

TEST(PartialSolve, NullDeltaLeavesTheAppliedStepAlone) {
  Solved s;
  s.solve.run(&s.p.tree, true, 0.001, 0.0, nullptr, &s.p.threads);
  for (const auto& d : s.delta) EXPECT_EQ(d, Eigen::Vector3d::Zero());
}

TEST(PartialSolve, WildfireSkipsCliquesBelowUnchangedSeparators) {
  Solved s;
  s.solve.run(&s.p.tree, true, 0.001, 0.0, &s.delta, &s.p.threads);
  ASSERT_GT(s.p.tree.num_cliques, 3);
  // Nothing dirty, nothing moved: no clique is entered.
  EXPECT_EQ(s.solve.run(&s.p.tree, false, 0.001, 0.0, &s.delta, &s.p.threads).solved, 0);
  // The root re-eliminated (dirty) with the same values: only the root is solved, since no
  // frontal moved by α from the value its subtree was solved with.
  const int root = s.p.tree.roots[0];
  s.p.tree.cliques[root].dirty = true;
  EXPECT_EQ(s.solve.run(&s.p.tree, false, 0.001, 0.0, &s.delta, &s.p.threads).solved, 1);
  // The root's values moved by more than α as seen from below (a stale delta_seen): its
  // children are entered, and theirs only if they moved too; α = 0 enters every clique.
  for (int v : s.p.tree.cliques[root].frontals) s.solve.delta_seen[v].array() += 1.0;
  s.p.tree.cliques[root].dirty = true;
  // Expected: the root and every clique whose separator holds one of the root's frontals (the
  // others re-solve to the same values, which do not move by α).
  const auto& rf = s.p.tree.cliques[root].frontals;
  int expected = 1;
  for (const auto& c : s.p.tree.cliques)
    if (c.in_use && c.parent >= 0)
      expected += std::any_of(c.separator.begin(), c.separator.end(),
                              [&](int v) { return std::count(rf.begin(), rf.end(), v) > 0; });
  const int solved = s.solve.run(&s.p.tree, false, 0.001, 0.0, &s.delta, &s.p.threads).solved;
  EXPECT_EQ(solved, expected);
  EXPECT_LT(solved, s.p.tree.num_cliques);
  s.p.tree.cliques[root].dirty = true;
  EXPECT_EQ(s.solve.run(&s.p.tree, false, 0.0, 0.0, &s.delta, &s.p.threads).solved,
            s.p.tree.num_cliques);
  // The values are still the dense step.
  const Eigen::VectorXd x = s.p.denseStep();
  for (int v = 0; v < s.p.n(); ++v)
    EXPECT_LE((s.solve.delta_newton[v] - x.segment<3>(v * 3)).norm(), 1e-9 * (1 + x.norm()));
}

// A solve budget: the root's right-hand side changed (so every Δ below it moves), a budget of
// one clique's worth solves the root (re-eliminated: always solved) and defers its children;
// runs with nothing new work the backlog off, and it ends where a full solve does.
TEST(PartialSolve, ABudgetDefersAndTheBacklogEndsAtTheFullSolve) {
  Solved s;
  s.solve.run(&s.p.tree, true, 0.0, 0.0, &s.delta, &s.p.threads);
  auto& tree = s.p.tree;
  const int root = tree.roots[0];
  auto& rc = tree.cliques[root];
  for (int k = 0; k < rc.F; ++k) rc.dPtr()[k] += 0.5;
  rc.dirty = true;
  // Every clique overruns a budget of 1 entry: the root (dirty) spends it, and each later run
  // solves one clique of the backlog.
  const double budget = 1;
  auto out = s.solve.run(&tree, false, 0.0, budget, &s.delta, &s.p.threads);
  EXPECT_EQ(out.solved, 1);
  EXPECT_GT(out.deferred, 0);
  EXPECT_EQ(out.deferred, tree.num_deferred);
  int runs = 1, solved = out.solved;
  while (tree.num_deferred > 0 && runs < 10000) {
    out = s.solve.run(&tree, false, 0.0, budget, &s.delta, &s.p.threads);
    EXPECT_EQ(out.solved, 1);
    solved += out.solved;
    ++runs;
  }
  EXPECT_EQ(tree.num_deferred, 0);
  EXPECT_GT(runs, 2);
  EXPECT_GE(solved, tree.num_cliques);  // α = 0: every clique lies below the root's change
  const std::vector<Eigen::Vector3d> bounded = s.solve.delta_newton;
  s.solve.run(&tree, true, 0.0, 0.0, &s.delta, &s.p.threads);
  for (int v = 0; v < s.p.n(); ++v)
    EXPECT_LE((bounded[v] - s.solve.delta_newton[v]).cwiseAbs().maxCoeff(), 1e-12) << v;
}

// A deferred clique removed with its top (Alg. 4 step 1) passes the moves it had not seen to
// the orphans that hold them in their separator: they have not seen them either.
TEST(PartialSolve, ARemovedDeferredCliquePassesItsUnseenMovesToItsOrphans) {
  Solved s;
  auto& tree = s.p.tree;
  // A clique below the root with a cached child that shares one of its separator variables.
  int c = -1, child = -1, v = -1;
  for (int id = 0; id < static_cast<int>(tree.cliques.size()) && c < 0; ++id) {
    const auto& k = tree.cliques[id];
    if (!k.in_use || k.parent < 0) continue;
    for (int ch : k.children)
      for (int x : tree.cliques[ch].separator)
        if (c < 0 && tree.cliques[ch].cached &&
            std::count(k.separator.begin(), k.separator.end(), x) > 0) {
          c = id;
          child = ch;
          v = x;
        }
  }
  ASSERT_GE(c, 0);
  tree.addUnseen(c, v);
  tree.addUnseen(c, v);  // once
  EXPECT_EQ(tree.num_deferred, 1);
  EXPECT_EQ(tree.cliques[c].unseen, std::vector<int>{v});
  bayestree::BayesTree<3>::Top top;
  tree.removeTop({c}, &top);
  EXPECT_FALSE(tree.cliques[c].in_use);
  EXPECT_TRUE(tree.cliques[c].unseen.empty());
  ASSERT_EQ(std::count(top.orphans.begin(), top.orphans.end(), child), 1);
  int holding = 0;
  for (int o : top.orphans) {
    const auto& sep = tree.cliques[o].separator;
    const bool holds = std::count(sep.begin(), sep.end(), v) > 0;
    holding += holds;
    EXPECT_EQ(tree.cliques[o].unseen, holds ? std::vector<int>{v} : std::vector<int>{}) << o;
  }
  EXPECT_GE(holding, 1);
  EXPECT_EQ(tree.num_deferred, holding);
}

TEST(PartialSolve, ResetVariableZeroesItsDelta) {
  Solved s;
  s.solve.run(&s.p.tree, true, 0.001, 0.0, &s.delta, &s.p.threads);
  s.solve.resetVariable(3);
  EXPECT_EQ(s.solve.delta_newton[3], Eigen::Vector3d::Zero());
  EXPECT_EQ(s.solve.delta_seen[3], Eigen::Vector3d::Zero());
}

}  // namespace
}  // namespace arbor
