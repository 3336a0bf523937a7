// The re-ordering decay watch (bayestree/ordering_decay.h): a fresh ordering's cost is that of
// the whole graph eliminated afresh; the watch compares only past decay × its references, sets
// reorderDue past the inline decay and jobWanted past the background one, and measures from the
// tree once it compared or the tree was ordered afresh.
#include <vector>

#include <gtest/gtest.h>

#include "arbor_slam/bayestree/ordering_decay.h"
#include "bayes_tree_units.h"

namespace arbor {
namespace {

using bayestree::DecayGraph;
using bayestree::DecayRule;
using bayestree::OrderingDecay;
using testing::SmallProblem;

// A graph whose tree was eliminated whole in a fresh (CCOLAMD) ordering.
struct Eliminated {
  SmallProblem p{400, 150, 7};
  bayestree::TopElimination<SE2> elimination;
  std::vector<int> slot;
  Eliminated() : slot(static_cast<size_t>(p.n()), -1) {
    p.linearizeAll();
    p.eliminateAll(&elimination);
  }
  DecayGraph<SE2> graph() { return {p.factors, p.fixed, 1 << 30, 0.0, &slot}; }
};

DecayRule inlineRule(double decay) { return {decay, false, 0}; }

TEST(OrderingDecay, FreshCostIsTheWholeGraphEliminatedAfresh) {
  Eliminated e;
  OrderingDecay<SE2> watch;
  double doubles = 0;
  const double flops = watch.freshOrderingCost(e.p.tree, e.graph(), &doubles);
  EXPECT_GT(e.p.tree.flops, 1e6);  // past the watch's floor
  EXPECT_NEAR(flops, e.p.tree.flops, 1e-9 * e.p.tree.flops);
  EXPECT_NEAR(doubles, e.p.tree.doubles, 1e-9 * e.p.tree.doubles);
  for (int s : e.slot) EXPECT_EQ(s, -1);  // the scratch is restored
}

TEST(OrderingDecay, FactorsOutOfTheStructureCostNothing) {
  Eliminated e;
  OrderingDecay<SE2> watch;
  double all_doubles = 0, fewer_doubles = 0;
  const double all = watch.freshOrderingCost(e.p.tree, e.graph(), &all_doubles);
  for (int f = e.p.n() - 1; f < e.p.factors.numFactors(); ++f) e.p.factors.detach(f);  // closures
  const double fewer = watch.freshOrderingCost(e.p.tree, e.graph(), &fewer_doubles);
  EXPECT_LT(fewer, all);
  EXPECT_LT(fewer_doubles, all_doubles);
}

TEST(OrderingDecay, ComparesOnlyPastDecayTimesTheReferences) {
  Eliminated e;
  OrderingDecay<SE2> watch;
  watch.orderedAfresh(e.p.tree, false);
  const double fresh = e.p.tree.flops;
  e.p.tree.flops = 1.9 * fresh;  // decayed, but not past 2× the reference: not compared
  watch.check(e.p.tree, e.graph(), inlineRule(2));
  EXPECT_FALSE(watch.reorderDue());
  e.p.tree.flops = 2.1 * fresh;  // past it: compared with the fresh ordering, past 2×
  watch.check(e.p.tree, e.graph(), inlineRule(2));
  EXPECT_TRUE(watch.reorderDue());
  EXPECT_FALSE(watch.jobWanted());
}

TEST(OrderingDecay, ATreeNoWorseThanFreshIsNotReordered) {
  Eliminated e;
  OrderingDecay<SE2> watch;  // references 0: compared at the first check past the floor
  watch.check(e.p.tree, e.graph(), inlineRule(1.5));
  EXPECT_FALSE(watch.reorderDue());
  // The references became the tree's: a decay to 1.4× is not even compared.
  e.p.tree.flops *= 1.4;
  watch.check(e.p.tree, e.graph(), inlineRule(1.5));
  EXPECT_FALSE(watch.reorderDue());
}

TEST(OrderingDecay, OffAtDecayZero) {
  Eliminated e;
  OrderingDecay<SE2> watch;
  e.p.tree.flops *= 100;
  watch.check(e.p.tree, e.graph(), inlineRule(0));
  EXPECT_FALSE(watch.reorderDue());
  EXPECT_FALSE(watch.jobWanted());
}

TEST(OrderingDecay, TheSoonerBackgroundDecayWantsAJobThenTheInlineOneReorders) {
  Eliminated e;
  OrderingDecay<SE2> watch;
  watch.orderedAfresh(e.p.tree, false);
  const DecayRule rule{4, true, 1.5};
  const double fresh = e.p.tree.flops;
  e.p.tree.flops = 2 * fresh;  // past the background decay, not the inline one
  watch.check(e.p.tree, e.graph(), rule);
  EXPECT_TRUE(watch.jobWanted());
  EXPECT_FALSE(watch.reorderDue());
  e.p.tree.flops = 5 * fresh;  // still wanted (no tree came in), now past the inline decay
  watch.check(e.p.tree, e.graph(), rule);
  EXPECT_TRUE(watch.reorderDue());
  watch.reorderingStarted();
  EXPECT_FALSE(watch.reorderDue());
  EXPECT_TRUE(watch.jobWanted());
}

TEST(OrderingDecay, AFreshTreeSettlesWhatWasFound) {
  Eliminated e;
  OrderingDecay<SE2> watch;
  watch.orderedAfresh(e.p.tree, false);
  e.p.tree.flops *= 5;
  watch.check(e.p.tree, e.graph(), {4, true, 1.5});
  ASSERT_TRUE(watch.jobWanted());
  watch.orderedAfresh(e.p.tree, /*job_in_flight=*/true);  // the job's tree will settle it
  EXPECT_TRUE(watch.jobWanted());
  watch.orderedAfresh(e.p.tree, false);
  EXPECT_FALSE(watch.jobWanted());
  e.p.tree.flops *= 5;
  watch.check(e.p.tree, e.graph(), inlineRule(2));
  ASSERT_TRUE(watch.reorderDue());
  watch.adoptedFresh(e.p.tree);
  EXPECT_FALSE(watch.reorderDue());
  EXPECT_FALSE(watch.jobWanted());
}

}  // namespace
}  // namespace arbor
