// The top elimination (bayestree/top_elimination.h): eliminating a whole small graph gives a
// valid Bayes tree whose conditionals satisfy RᵀR = H and Rᵀd = g (the dense Hessian), with one
// thread or three (bit for bit the same); re-eliminating a removed top with its orphans gives
// the same factorisation; a singular clique is damped and counted.
#include <vector>

#include <gtest/gtest.h>

#include "arbor_slam/bayestree/top_elimination.h"
#include "bayes_tree_units.h"

namespace arbor {
namespace {

using testing::SmallProblem;

void expectFactorsHessian(const SmallProblem& p, double tol) {
  Eigen::MatrixXd H, R;
  Eigen::VectorXd g, d;
  p.denseSystem(&H, &g);
  p.treeFactor(&R, &d);
  EXPECT_LE((R.transpose() * R - H).norm(), tol * H.norm());
  EXPECT_LE((R.transpose() * d - g).norm(), tol * (1 + g.norm()));
}

TEST(TopElimination, WholeGraphGivesRtREqualToTheHessian) {
  for (unsigned seed : {1u, 2u, 3u}) {
    SmallProblem p(30, 15, seed);
    p.linearizeAll();
    bayestree::TopElimination<SE2> elimination;
    const auto out = p.eliminateAll(&elimination);
    EXPECT_EQ(out.variables, 29);
    EXPECT_EQ(out.cliques, p.tree.num_cliques);
    EXPECT_EQ(out.indeterminate, 0);
    p.tree.checkInvariants(p.factors.factors, p.factors.attached, p.fixed,
                           [](int) { return false; });
    expectFactorsHessian(p, 1e-10);
  }
}

TEST(TopElimination, LinearisesWhatItIsGiven) {
  SmallProblem p(12, 6, 4), q(12, 6, 4);
  q.linearizeAll();
  bayestree::TopElimination<SE2> e1, e2;
  std::vector<int> all;
  for (int f = 0; f < p.factors.numFactors(); ++f) all.push_back(f);
  const std::vector<int> top = p.variables(), orphans;
  const bayestree::TopElimination<SE2>::Input in{top,     orphans, nullptr, all,
                                                 p.theta, p.fixed, 1 << 30};
  e1.run(in, &p.tree, &p.factors, &p.threads);
  q.eliminateAll(&e2);
  for (int c = 0; c < static_cast<int>(p.tree.cliques.size()); ++c)
    EXPECT_EQ(p.tree.cliques[c].R(), q.tree.cliques[c].R());
}

TEST(TopElimination, ThreadsGiveTheSameFactorBitForBit) {
  SmallProblem a(200, 120, 7), b(200, 120, 7, /*lanes=*/3);
  a.linearizeAll();
  b.linearizeAll();
  bayestree::TopElimination<SE2> ea, eb;
  a.eliminateAll(&ea);
  b.eliminateAll(&eb);
  ASSERT_EQ(a.tree.cliques.size(), b.tree.cliques.size());
  for (size_t c = 0; c < a.tree.cliques.size(); ++c) {
    EXPECT_EQ(a.tree.cliques[c].R(), b.tree.cliques[c].R());
    EXPECT_EQ(a.tree.cliques[c].d(), b.tree.cliques[c].d());
  }
}

TEST(TopElimination, ReeliminatingATopWithItsOrphansKeepsTheFactorisation) {
  SmallProblem p(40, 20, 9);
  p.linearizeAll();
  bayestree::TopElimination<SE2> elimination;
  p.eliminateAll(&elimination);
  // Remove the top above a leaf's parent and re-eliminate it (constrained: the leaf's
  // variables last), the rest of the tree hanging back as orphans.
  int leaf = -1;
  for (int c = 0; c < static_cast<int>(p.tree.cliques.size()); ++c)
    if (p.tree.cliques[c].in_use && p.tree.cliques[c].children.empty() &&
        p.tree.cliques[c].parent >= 0)
      leaf = p.tree.cliques[c].parent;
  ASSERT_GE(leaf, 0);
  std::vector<char> last(p.n(), 0);
  for (int v : p.tree.cliques[leaf].frontals) last[v] = 1;
  bayestree::BayesTree<3>::Top top;
  p.tree.removeTop({leaf}, &top);
  EXPECT_FALSE(top.orphans.empty());
  const std::vector<int> none;
  const bayestree::TopElimination<SE2>::Input in{top.variables, top.orphans, &last,  none,
                                                 p.theta,       p.fixed,     1 << 30};
  const auto out = elimination.run(in, &p.tree, &p.factors, &p.threads);
  EXPECT_EQ(out.variables, static_cast<int>(top.variables.size()));
  p.tree.checkInvariants(p.factors.factors, p.factors.attached, p.fixed, [](int) { return false; });
  expectFactorsHessian(p, 1e-10);
}

TEST(TopElimination, SingularCliqueIsDampedAndCounted) {
  SmallProblem p(3, 0, 2);
  // A pose with no factor at all: its Hessian block is zero.
  p.theta.push_back(SE2(5, 5, 0));
  p.fixed.push_back(0);
  p.addVariable();
  p.linearizeAll();
  bayestree::TopElimination<SE2> elimination;
  const auto out = p.eliminateAll(&elimination);
  EXPECT_GE(out.indeterminate, 1);
  EXPECT_TRUE(p.tree.cliques[p.tree.clique_of[3]].damped);
}

}  // namespace
}  // namespace arbor
