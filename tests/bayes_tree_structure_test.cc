// The Bayes tree's structure (bayestree/bayes_tree.h) on a hand-built tree: removeTop's top
// variables and orphans, re-attaching an orphan, the free list, and checkInvariants firing — with
// a message naming the violation — on trees corrupted one way at a time.
#include <functional>
#include <stdexcept>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "arbor_slam/bayestree/bayes_tree.h"
#include "arbor_slam/core/factor.h"
#include "arbor_slam/core/se2.h"

namespace arbor {
namespace {

using Tree = bayestree::BayesTree<3>;

// Poses 0..6, pose 6 fixed. Cliques (frontals : separator):
//   c0 = {4, 5} : {}        root
//   c1 = {2, 3} : {4}       child of c0
//   c2 = {1}    : {2}       child of c1
//   c3 = {0}    : {5}       child of c0
struct HandBuilt {
  Tree tree;
  std::vector<char> fixed{0, 0, 0, 0, 0, 0, 1};
  std::vector<Factor<SE2>> factors;
  int c[4];

  HandBuilt() {
    for (int v = 0; v < 7; ++v) tree.addVariable();
    for (int& id : c) id = tree.allocClique();
    set(c[0], {4, 5}, {}, -1);
    set(c[1], {2, 3}, {4}, c[0]);
    set(c[2], {1}, {2}, c[1]);
    set(c[3], {0}, {5}, c[0]);
    tree.roots.push_back(c[0]);
    for (auto [i, j] :
         std::vector<std::pair<int, int>>{{0, 5}, {1, 2}, {2, 3}, {3, 4}, {4, 5}, {1, 6}})
      factors.push_back(
          RelativePoseEdge<SE2>::make(i, j, SE2(1, 0, 0), Eigen::Matrix3d::Identity()));
  }
  void set(int id, std::vector<int> frontals, std::vector<int> separator, int parent) {
    auto& k = tree.cliques[id];
    k.frontals = std::move(frontals);
    k.separator = std::move(separator);
    k.parent = parent;
    if (parent >= 0) tree.cliques[parent].children.push_back(id);
    for (int v : k.frontals) tree.clique_of[v] = id;
    tree.countClique(k);  // as the top elimination does
    k.allocate();
  }
  // Makes clique `id` one without a cached factor, its doubles recounted (as the top elimination
  // counts such a clique); its storage still holds the cached factor until dropCachedFactor.
  void keepNoCachedFactor(int id) {
    auto& k = tree.cliques[id];
    tree.countClique(k.frontals.size(), k.separator.size(), -1.0, true);
    k.cached = false;
    tree.countClique(k.frontals.size(), k.separator.size(), 1.0, false);
  }
  void check() const {
    tree.checkInvariants(factors, std::vector<char>(factors.size(), 1), fixed,
                         [](int) { return false; });
  }
  // The message checkInvariants throws (empty if none).
  std::string violation() const {
    try {
      check();
    } catch (const std::logic_error& e) {
      return e.what();
    }
    return "";
  }
};

TEST(BayesTreeStructure, HandBuiltTreeIsValid) {
  HandBuilt t;
  EXPECT_EQ(t.violation(), "");
  EXPECT_EQ(t.tree.num_cliques, 4);
  EXPECT_TRUE(t.tree.isAncestorOrSelf(t.c[0], t.c[2]));
  EXPECT_FALSE(t.tree.isAncestorOrSelf(t.c[3], t.c[2]));
}

TEST(BayesTreeStructure, RemoveTopTakesTheMarkedCliquesAndTheirAncestors) {
  HandBuilt t;
  Tree::Top top;
  top.variables = {7};  // the caller's new variables come first
  t.tree.removeTop({t.c[2]}, &top);
  // c2, c1, c0 removed (in that order): their frontals; c3 hangs below the removed root.
  EXPECT_EQ(top.variables, (std::vector<int>{7, 1, 2, 3, 4, 5}));
  EXPECT_EQ(top.orphans, (std::vector<int>{t.c[3]}));
  EXPECT_TRUE(t.tree.roots.empty());
  EXPECT_EQ(t.tree.num_cliques, 1);
  EXPECT_EQ(t.tree.free_cliques.size(), 3u);
  EXPECT_FALSE(t.tree.cliques[t.c[0]].in_use);
  // A recycled clique comes off the free list.
  const int id = t.tree.allocClique();
  EXPECT_TRUE(id == t.c[0] || id == t.c[1] || id == t.c[2]);
  EXPECT_EQ(t.tree.num_cliques, 2);
}

TEST(BayesTreeStructure, RemoveTopOfTwoBranchesRemovesEachCliqueOnce) {
  HandBuilt t;
  Tree::Top top;
  t.tree.removeTop({t.c[3], t.c[1], t.c[0]}, &top);
  EXPECT_EQ(top.variables, (std::vector<int>{0, 4, 5, 2, 3}));
  EXPECT_EQ(top.orphans, (std::vector<int>{t.c[2]}));
  EXPECT_EQ(t.tree.num_cliques, 1);
}

// A clique without a cached factor cannot be an orphan: it leaves with its parent, and its own
// children (which keep theirs) are the orphans.
TEST(BayesTreeStructure, RemoveTopTakesAChildWithoutACachedFactorAlong) {
  HandBuilt t;
  t.keepNoCachedFactor(t.c[1]);
  auto& c1 = t.tree.cliques[t.c[1]];
  c1.dropCachedFactor();
  EXPECT_EQ(c1.ldh, 0);
  EXPECT_EQ(c1.storage.size(), Tree::CliqueD::sizeFor(c1.F, c1.ld, 0));
  EXPECT_EQ(t.violation(), "");
  const double doubles_before = t.tree.doubles;
  Tree::Top top;
  t.tree.removeTop({t.c[3]}, &top);  // c3 and c0; c1 (no cached factor) along; c2 the orphan
  EXPECT_EQ(top.variables, (std::vector<int>{0, 4, 5, 2, 3}));
  EXPECT_EQ(top.orphans, (std::vector<int>{t.c[2]}));
  EXPECT_EQ(t.tree.num_cliques, 1);
  // Only c2 is left, so the doubles are its own: the removed ones were taken off as counted.
  EXPECT_NEAR(t.tree.doubles, Tree::cliqueDoubles(1, 1), 1e-9);
  EXPECT_LT(t.tree.doubles, doubles_before);
}

TEST(BayesTreeStructure, CheckInvariantsNamesACliqueWithoutCachedFactorThatHoldsOne) {
  HandBuilt t;
  t.keepNoCachedFactor(t.c[1]);
  // Not dropped: its storage still holds the cached factor.
  EXPECT_NE(t.violation().find("clique 1 has matrices of the wrong size"), std::string::npos)
      << t.violation();
}

TEST(BayesTreeStructure, KeepsCachedFactorByItsRatioToTheConditional) {
  Tree tree;
  EXPECT_TRUE(tree.keepsCachedFactor(1, 100));  // ratio 0: every clique keeps it
  tree.cached_factors.max_ratio = 2;
  // F = 3, S = 6: S² = 36 ≤ 2·3·9 = 54; S = 9: 81 > 2·3·12 = 72.
  EXPECT_TRUE(tree.keepsCachedFactor(1, 2));
  EXPECT_FALSE(tree.keepsCachedFactor(1, 3));
  EXPECT_TRUE(tree.keepsCachedFactor(1, 0));  // a root
  EXPECT_DOUBLE_EQ(Tree::cliqueDoubles(1, 3, false), 3.0 * 12 + 3);
  EXPECT_DOUBLE_EQ(Tree::cliqueDoubles(1, 3, true), 3.0 * 12 + 3 + 81 + 9);
}

TEST(BayesTreeStructure, AttachOrphanLinksBothWays) {
  HandBuilt t;
  Tree::Top top;
  t.tree.removeTop({t.c[3]}, &top);  // removes c3 and c0; c1 is an orphan
  ASSERT_EQ(top.orphans, (std::vector<int>{t.c[1]}));
  const int root = t.tree.allocClique();
  t.set(root, {0, 4, 5}, {}, -1);
  t.tree.roots.push_back(root);
  t.tree.attachOrphan(t.c[1], root);
  EXPECT_EQ(t.tree.cliques[t.c[1]].parent, root);
  EXPECT_EQ(t.violation(), "");
}

TEST(BayesTreeStructure, CliquesContainingFollowsTheSeparators) {
  HandBuilt t;
  std::vector<int> marked;
  t.tree.cliquesContaining({4}, &marked);  // frontal in c0, in c1's separator, not in c2's
  EXPECT_EQ(marked, (std::vector<int>{t.c[0], t.c[1]}));
}

TEST(BayesTreeStructure, CheckInvariantsNamesABrokenParentChildLink) {
  HandBuilt t;
  t.tree.cliques[t.c[1]].children.clear();
  EXPECT_NE(t.violation().find("clique 2 is not among its parent's children"), std::string::npos)
      << t.violation();
}

TEST(BayesTreeStructure, CheckInvariantsNamesAVariableFrontalTwice) {
  HandBuilt t;
  t.set(t.c[3], {0, 1}, {5}, -2);  // parent unchanged below
  t.tree.cliques[t.c[3]].parent = t.c[0];
  t.tree.clique_of[1] = t.c[2];  // as before: c2 holds it, and c3 holds it too
  EXPECT_NE(t.violation().find("variable 1 is frontal in more than one clique"), std::string::npos)
      << t.violation();
}

TEST(BayesTreeStructure, CheckInvariantsNamesABrokenRunningIntersection) {
  HandBuilt t;
  t.tree.cliques[t.c[2]].separator = {5};  // 5 is not in c1 = {2, 3 : 4}
  EXPECT_NE(
      t.violation().find("separator variable 5 not in parent clique 1 (running intersection)"),
      std::string::npos)
      << t.violation();
}

TEST(BayesTreeStructure, CheckInvariantsNamesAFactorInNoClique) {
  HandBuilt t;
  t.factors.push_back(RelativePoseEdge<SE2>::make(1, 5, SE2(1, 0, 0), Eigen::Matrix3d::Identity()));
  EXPECT_NE(t.violation().find("factor 6 (1, 5) lies in no clique"), std::string::npos)
      << t.violation();
}

TEST(BayesTreeStructure, CheckInvariantsNamesARootWithASeparator) {
  HandBuilt t;
  t.set(t.c[0], {4, 5}, {0}, -1);
  EXPECT_NE(t.violation().find("root clique 0 has a non-empty separator"), std::string::npos)
      << t.violation();
}

TEST(BayesTreeStructure, CheckInvariantsNamesAFixedFrontal) {
  HandBuilt t;
  t.fixed[1] = 1;
  EXPECT_NE(t.violation().find("clique 2 has a bad frontal 1"), std::string::npos) << t.violation();
}

TEST(BayesTreeStructure, MemoryCountsTheCliquesInUse) {
  HandBuilt t;
  const TreeMemory m = t.tree.memory();
  EXPECT_EQ(m.cliques, 4);
  EXPECT_EQ(m.free_cliques, 0);
  EXPECT_EQ(m.max_frontal_dim, 6);
  EXPECT_EQ(m.max_separator_dim, 3);
  EXPECT_DOUBLE_EQ(m.mean_separator_dim, 9.0 / 4);
  size_t bytes = 0;
  for (const auto& k : t.tree.cliques) bytes += k.storage.size() * sizeof(double);
  EXPECT_EQ(m.clique_bytes, bytes);
  EXPECT_GE(m.clique_bytes_reserved, m.clique_bytes);
}

}  // namespace
}  // namespace arbor
