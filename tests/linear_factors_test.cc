// The linearised factors (bayestree/linear_factors.h): each factor's Hessian-form blocks equal
// AᵀA and −Aᵀr of its whitened linearisation, the threaded linearisation equals the one-by-one
// one bit for bit, and assembledAt puts each factor at exactly one frontal of a clique.
#include <vector>

#include <gtest/gtest.h>

#include "bayes_tree_units.h"

namespace arbor {
namespace {

using testing::SmallProblem;

TEST(LinearFactors, BlocksAreAtAAndMinusAtr) {
  SmallProblem p(8, 4, 11);
  p.linearizeAll();
  for (int f = 0; f < p.factors.numFactors(); ++f) {
    const Factor<SE2>& e = p.factors.factors[f];
    Factor<SE2>::Linearization A;
    e.linearize(p.theta, &A);
    const auto& L = p.factors.lin[f];
    for (int k = 0; k < e.arity(); ++k) {
      EXPECT_LE((L.g[k] - (-A.A[k].transpose() * A.r)).norm(), 1e-12 * (1 + L.g[k].norm()));
      for (int l = 0; l < e.arity(); ++l) {
        const Eigen::Matrix3d expect = A.A[k].transpose() * A.A[l];
        EXPECT_LE((L.at(k, l) - expect).norm(), 1e-12 * (1 + expect.norm())) << f << " " << k << l;
      }
    }
  }
}

TEST(LinearFactors, VariableListsHoldEachFactorAtEachKey) {
  SmallProblem p(6, 3, 3);
  for (int f = 0; f < p.factors.numFactors(); ++f)
    for (int k = 0; k < p.factors.factors[f].arity(); ++k) {
      const auto& list = p.factors.var_factors[p.factors.factors[f].key(k)];
      EXPECT_EQ(std::count(list.begin(), list.end(), f), 1);
    }
}

TEST(LinearFactors, ThreadedLinearisationEqualsOneByOne) {
  SmallProblem a(300, 600, 5), b(300, 600, 5);  // > 4 chunks of 128: shared among threads
  bayestree::UpdateThreads threads(3);
  for (int v = 0; v < b.n(); ++v) threads.addVariable();
  std::vector<int> all;
  for (int f = 0; f < b.factors.numFactors(); ++f) all.push_back(f);
  bool alongside = false;
  b.factors.linearizeAll(all, b.theta, &threads, [&] { alongside = true; });
  a.linearizeAll();
  EXPECT_TRUE(alongside);
  for (int f = 0; f < a.factors.numFactors(); ++f) {
    EXPECT_EQ(a.factors.lin[f].H[0], b.factors.lin[f].H[0]) << f;
    EXPECT_EQ(a.factors.lin[f].g[0], b.factors.lin[f].g[0]) << f;
  }
}

TEST(LinearFactors, AssembledAtTheFirstKeyOfTheClique) {
  SmallProblem p(4, 0, 1);
  std::vector<int> slot(p.n(), -1);
  const Factor<SE2> e =
      RelativePoseEdge<SE2>::make(1, 2, SE2(1, 0, 0), Eigen::Matrix3d::Identity());
  const Factor<SE2> to_fixed =
      RelativePoseEdge<SE2>::make(0, 3, SE2(1, 0, 0), Eigen::Matrix3d::Identity());
  using LF = bayestree::LinearizedFactors<SE2>;
  // A clique {2, 1 : 3}: 2 eliminated first, so the factor enters at 2, not at 1.
  slot[2] = 0;
  slot[1] = 1;
  slot[3] = 2;
  EXPECT_TRUE(LF::assembledAt(e, 2, slot, p.fixed));
  EXPECT_FALSE(LF::assembledAt(e, 1, slot, p.fixed));
  // A key outside the clique (slot −1): the factor is not this clique's.
  slot[1] = -1;
  EXPECT_FALSE(LF::assembledAt(e, 2, slot, p.fixed));
  // A fixed key is a constant: a unary term at the other key.
  EXPECT_TRUE(LF::assembledAt(to_fixed, 3, slot, p.fixed));
}

}  // namespace
}  // namespace arbor
