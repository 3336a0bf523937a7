// Tests of bayestree/elimination_plan.h: the constrained orderings (CCOLAMD, nested dissection)
// and the symbolic elimination they feed.

#include <algorithm>
#include <limits>
#include <numeric>
#include <vector>

#include "arbor_slam/bayestree/elimination_plan.h"
#include "arbor_slam/bayestree/tree_shape.h"

#include <gtest/gtest.h>

namespace arbor::bayestree {
namespace {

// A k×k grid of variables, one row per edge (a 2D mesh: where nested dissection shines).
RowList gridRows(int k) {
  RowList rows;
  for (int r = 0; r < k; ++r)
    for (int c = 0; c < k; ++c) {
      const int v = r * k + c;
      if (c + 1 < k) {
        rows.add(v);
        rows.add(v + 1);
        rows.endRow();
      }
      if (r + 1 < k) {
        rows.add(v);
        rows.add(v + k);
        rows.endRow();
      }
    }
  return rows;
}

bool isPermutation(std::vector<int> order, int n) {
  std::sort(order.begin(), order.end());
  std::vector<int> expected(n);
  std::iota(expected.begin(), expected.end(), 0);
  return order == expected;
}

// Σ over cliques of f³/3 + f²s + fs² (f frontals, s separator): the dense work of the
// elimination, in units of one variable.
double eliminationWork(const EliminationPlan& plan) {
  double work = 0;
  for (const SymbolicClique& c : plan.cliques) {
    const double f = static_cast<double>(c.frontals.size());
    const double s = static_cast<double>(c.separator.size());
    work += f * f * f / 3 + f * f * s + f * s * s;
  }
  return work;
}

TEST(EliminationPlan, NestedDissectionIsAConstrainedPermutation) {
  const int k = 30, n = k * k;
  const RowList rows = gridRows(k);
  std::vector<int> group(n, 0);
  const std::vector<int> last = {17, 450, 899, 3};
  for (int v : last) group[v] = 1;
  const std::vector<int> order = constrainedNestedDissection(n, rows, group);
  ASSERT_TRUE(isPermutation(order, n));
  std::vector<int> tail(order.end() - 4, order.end());
  std::sort(tail.begin(), tail.end());
  std::vector<int> expected = last;
  std::sort(expected.begin(), expected.end());
  EXPECT_EQ(tail, expected) << "the constrained variables go last";
}

// On a large grid (on small ones minimum degree is as good or better).
TEST(EliminationPlan, NestedDissectionDoesLessWorkThanMinimumDegreeOnALargeGrid) {
  const int k = 120, n = k * k;
  const RowList rows = gridRows(k);
  const std::vector<int> group(n, 0);
  const EliminationPlan nd = planElimination(n, rows, constrainedNestedDissection(n, rows, group));
  const EliminationPlan md = planElimination(n, rows, constrainedColamd(n, rows, group));
  EXPECT_LT(eliminationWork(nd), eliminationWork(md));
  // The same variables, each frontal in exactly one clique.
  std::vector<int> seen(n, 0);
  for (const SymbolicClique& c : nd.cliques)
    for (int v : c.frontals) ++seen[v];
  EXPECT_TRUE(std::all_of(seen.begin(), seen.end(), [](int x) { return x == 1; }));
}

TEST(EliminationPlan, SmallProblemsKeepMinimumDegree) {
  const int k = 6, n = k * k;  // 36 variables: below nested dissection's minimum
  const RowList rows = gridRows(k);
  std::vector<int> group(n, 0);
  group[5] = 1;
  EXPECT_EQ(constrainedNestedDissection(n, rows, group), constrainedColamd(n, rows, group));
}

TEST(EliminationPlan, RejectsAGroupOfTheWrongSize) {
  const RowList rows = gridRows(10);
  EXPECT_THROW(constrainedNestedDissection(100, rows, std::vector<int>(99, 0)),
               std::invalid_argument);
}

// planTop (bayestree/tree_shape.h): nested dissection from nested_dissection_min on; below it
// CCOLAMD, and for a heavy plan (more than try_flops flops per variable) whichever of the two
// costs fewer flops. A 100 × 100 lattice is such a plan: nested dissection beats minimum degree
// on it (not yet at 60 × 60), and the constrained variables stay last either way.
TEST(PlanTop, TriesNestedDissectionOnHeavyPlansAndKeepsTheCheaper) {
  constexpr int side = 100, n = side * side;
  const RowList rows = gridRows(side);
  std::vector<int> group(n, 0);
  constexpr int last = 4;  // the variables of the new factors, ordered last
  for (int c = 0; c < last; ++c) group[(side - 1) * side + c] = 1;
  const auto colamd = planElimination(n, rows, constrainedColamd(n, rows, group));
  const auto nd = planElimination(n, rows, constrainedNestedDissection(n, rows, group));
  const double colamd_flops = treeShape<3>(colamd, 0).flops;
  const double nd_flops = treeShape<3>(nd, 0).flops;
  ASSERT_LT(nd_flops, colamd_flops) << "a lattice where nested dissection wins: this test's case";
  const int never = std::numeric_limits<int>::max();
  // Light enough, or no try: CCOLAMD's plan.
  EXPECT_EQ(planTop<3>(n, rows, group, never, 0).order, colamd.order);
  EXPECT_EQ(planTop<3>(n, rows, group, never, 2 * colamd_flops / n).order, colamd.order);
  // Heavier than the bound: the cheaper, nested dissection's.
  const auto tried = planTop<3>(n, rows, group, never, 0.5 * colamd_flops / n);
  EXPECT_EQ(tried.order, nd.order);
  // At nested_dissection_min: nested dissection without a try.
  EXPECT_EQ(planTop<3>(n, rows, group, n, 0).order, nd.order);
  for (const auto* plan : {&colamd, &tried}) {
    for (int k = n - last; k < n; ++k) EXPECT_EQ(group[plan->order[k]], 1) << k;
  }
}

TEST(PathCost, CountsTheRowsFromTheFactorsVariableUpAndEveryRowAbove) {
  // Two variables in one clique (0 then 1, no separator), D = 3: the blocks of [R] are
  // R₀₀ R₀₁ / R₁₁, 9 doubles each.
  RowList rows;
  rows.add(0);
  rows.add(1);
  rows.endRow();
  const EliminationPlan plan = planElimination(2, rows, {0, 1});
  ASSERT_EQ(plan.cliques.size(), 1u);
  std::vector<int> seen(1, -1);
  const PathCost from0 = pathCost<3>(plan, 0, 0, &seen, 0);
  EXPECT_EQ(from0.cliques, 1);
  EXPECT_DOUBLE_EQ(from0.rewritten_doubles, 27);  // both block rows
  EXPECT_DOUBLE_EQ(from0.rankUpdateFlops<3>(), 2 * 3 * 27);
  EXPECT_DOUBLE_EQ(from0.reelimination_flops, 6.0 * 6 * 6 / 3);
  const PathCost from1 = pathCost<3>(plan, 1, 1, &seen, 1);
  EXPECT_DOUBLE_EQ(from1.rewritten_doubles, 9);  // the last block row only
}

TEST(PathCost, ReachesTheUnionOfTheTwoPathsToTheRoot) {
  constexpr int side = 30, n = side * side;
  const RowList rows = gridRows(side);
  const std::vector<int> group(n, 0);
  const auto plan = planElimination(n, rows, constrainedNestedDissection(n, rows, group));
  std::vector<int> seen(plan.cliques.size(), -1);
  int stamp = 0;
  auto path = [&](int v) {  // the cliques from v's to the root, walked by hand
    std::vector<int> p;
    for (int c = plan.clique_of_variable[v]; c >= 0; c = plan.cliques[c].parent) p.push_back(c);
    return p;
  };
  const int a = 0, b = n - 1, c = n / 2 + side / 2;
  for (const auto& [u, v] : {std::pair{a, b}, std::pair{a, c}, std::pair{b, c}}) {
    std::vector<int> both = path(u), pv = path(v);
    both.insert(both.end(), pv.begin(), pv.end());
    std::sort(both.begin(), both.end());
    both.erase(std::unique(both.begin(), both.end()), both.end());
    double flops = 0;
    for (int k : both)
      flops += BayesTree<3>::cliqueFlops(plan.cliques[k].frontals.size(),
                                         plan.cliques[k].separator.size());
    const PathCost cost = pathCost<3>(plan, u, v, &seen, stamp++);
    EXPECT_EQ(cost.cliques, static_cast<int>(both.size())) << u << " " << v;
    EXPECT_NEAR(cost.reelimination_flops, flops, 1e-9 * flops);
    // Two paths cost at least the dearer one and at most both.
    const PathCost pu = pathCost<3>(plan, u, u, &seen, stamp++);
    const PathCost pv2 = pathCost<3>(plan, v, v, &seen, stamp++);
    EXPECT_GE(cost.rewritten_doubles, std::max(pu.rewritten_doubles, pv2.rewritten_doubles));
    EXPECT_LE(cost.rewritten_doubles, pu.rewritten_doubles + pv2.rewritten_doubles);
  }
}

}  // namespace
}  // namespace arbor::bayestree
