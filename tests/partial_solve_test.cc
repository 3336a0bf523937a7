// The partial state update (bayestree/partial_solve.h, IJRR 2012 Alg. 7): a full solve equals
// the dense Gauss–Newton step; with a wildfire threshold α the cliques below separators that did
// not move by α are skipped, and with α = 0 every clique below a changed one is solved.
#include <algorithm>
#include <vector>

#include <gtest/gtest.h>

#include "arbor/bayestree/partial_solve.h"
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
    const auto out = s.solve.run(&s.p.tree, /*full=*/true, 0.001, &s.delta, &s.p.threads);
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
  s.solve.run(&s.p.tree, true, 0.001, nullptr, &s.p.threads);
  for (const auto& d : s.delta) EXPECT_EQ(d, Eigen::Vector3d::Zero());
}

TEST(PartialSolve, WildfireSkipsCliquesBelowUnchangedSeparators) {
  Solved s;
  s.solve.run(&s.p.tree, true, 0.001, &s.delta, &s.p.threads);
  ASSERT_GT(s.p.tree.num_cliques, 3);
  // Nothing dirty, nothing moved: no clique is entered.
  EXPECT_EQ(s.solve.run(&s.p.tree, false, 0.001, &s.delta, &s.p.threads).solved, 0);
  // The root re-eliminated (dirty) with the same values: only the root is solved, since no
  // frontal moved by α from the value its subtree was solved with.
  const int root = s.p.tree.roots[0];
  s.p.tree.cliques[root].dirty = true;
  EXPECT_EQ(s.solve.run(&s.p.tree, false, 0.001, &s.delta, &s.p.threads).solved, 1);
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
  const int solved = s.solve.run(&s.p.tree, false, 0.001, &s.delta, &s.p.threads).solved;
  EXPECT_EQ(solved, expected);
  EXPECT_LT(solved, s.p.tree.num_cliques);
  s.p.tree.cliques[root].dirty = true;
  EXPECT_EQ(s.solve.run(&s.p.tree, false, 0.0, &s.delta, &s.p.threads).solved,
            s.p.tree.num_cliques);
  // The values are still the dense step.
  const Eigen::VectorXd x = s.p.denseStep();
  for (int v = 0; v < s.p.n(); ++v)
    EXPECT_LE((s.solve.delta_newton[v] - x.segment<3>(v * 3)).norm(), 1e-9 * (1 + x.norm()));
}

TEST(PartialSolve, ResetVariableZeroesItsDelta) {
  Solved s;
  s.solve.run(&s.p.tree, true, 0.001, &s.delta, &s.p.threads);
  s.solve.resetVariable(3);
  EXPECT_EQ(s.solve.delta_newton[3], Eigen::Vector3d::Zero());
  EXPECT_EQ(s.solve.delta_seen[3], Eigen::Vector3d::Zero());
}

}  // namespace
}  // namespace arbor
