// Issue 52's held-out protocol in `arbor bench robust --family` (tools/bench/world_families.h,
// family_bench.h): the seed ranges, each family's information scale, the generated cases, F*
// taken from the world's clean optimum, and the report's rows and summary. Small worlds, an
// oracle for the replay; no timing.
#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <set>
#include <stdexcept>

#include "arbor_slam/io/labels_file.h"
#include "arbor_slam/io/pose_graph_file.h"
#include "arbor_slam/tools/bench/ablation.h"
#include "arbor_slam/tools/bench/family_bench.h"
#include "arbor_slam/tools/bench/shared_data.h"
#include "arbor_slam/tools/bench/world_families.h"

namespace arbor {
namespace {

namespace fs = std::filesystem;

TEST(WorldFamilies, SeedRangesAreParsedAndBadOnesNamed) {
  EXPECT_EQ(bench::parseSeedRange("1-3"), (std::vector<std::uint64_t>{1, 2, 3}));
  EXPECT_EQ(bench::parseSeedRange("4-10").size(), 7u);
  EXPECT_EQ(bench::parseSeedRange("5"), std::vector<std::uint64_t>{5});
  for (const std::string bad : {"", "0-2", "3-1", "a", "1-", "-3", "1-2-3", "1.5"}) {
    try {
      bench::parseSeedRange(bad);
      ADD_FAILURE() << "'" << bad << "' accepted";
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find("--seeds must be A-B or A with 1 <= A <= B, not '" +
                                           bad + "'"),
                std::string::npos)
          << e.what();
    }
  }
}

TEST(WorldFamilies, EachSeedDrawsItsScaleWithinTheFamilysRange) {
  EXPECT_FALSE(bench::worldFamily("bicycle").has_value());
  for (const std::string& name : bench::worldFamilyNames()) {
    const auto family = bench::worldFamily(name);
    ASSERT_TRUE(family.has_value()) << name;
    std::set<double> scales;
    for (std::uint64_t seed = 1; seed <= 10; ++seed) {
      const double X = bench::familyInformationScale(*family, seed);
      EXPECT_EQ(X, bench::familyInformationScale(*family, seed));
      // Within the range up to the rounding to three significant digits.
      EXPECT_GE(X, family->scale_low * (1 - 5e-3)) << name << " seed " << seed;
      EXPECT_LE(X, family->scale_high * (1 + 5e-3)) << name << " seed " << seed;
      EXPECT_EQ(bench::familyWorldOptions(*family, seed).noise.information_scale, X);
      EXPECT_EQ(bench::familyWorldOptions(*family, seed).seed, seed);
      scales.insert(X);
    }
    EXPECT_GE(scales.size(), 8u) << name;  // the seeds spread over the range
  }
  // Cautious families write Ω below the noise's, the over-confident one above.
  EXPECT_LT(bench::worldFamily("vehicle")->scale_high, 1.0);
  EXPECT_LT(bench::worldFamily("small-loop")->scale_high, 1.0);
  EXPECT_GT(bench::worldFamily("over-confident")->scale_low, 1.0);
  EXPECT_EQ(bench::worldFamily("vehicle")->world.poses, 3000);
}

TEST(FamilyBench, GoalCoversTenAndFiftyPercentAndNinetyIn2D) {
  EXPECT_TRUE(bench::familyGoalCovers(2, 0.1));
  EXPECT_TRUE(bench::familyGoalCovers(3, 0.5));
  EXPECT_TRUE(bench::familyGoalCovers(2, 0.9));
  EXPECT_FALSE(bench::familyGoalCovers(3, 0.9));
}

TEST(FamilyBench, CasesAreTheWorldsWithTheirPlantedFilesAndFStarTheirCleanOptimum) {
  const fs::path out =
      fs::temp_directory_path() / ("arbor-bench-families-test-" + std::to_string(::getpid()));
  fs::remove_all(out);
  fs::create_directories(out);
  bench::FamilyPlan plan;
  plan.families = {"small-loop"};
  plan.dims = {2, 3};
  plan.seeds = {2};
  plan.fractions = {0.1};
  plan.policies = {sim::OutlierPolicy::kGroup};
  const auto cases = bench::generateFamilyCases(plan, out.string());
  ASSERT_EQ(cases.size(), 2u);
  EXPECT_EQ(cases[0].name, "small-loop-2d-s2_group_0.1");
  EXPECT_EQ(cases[1].name, "small-loop-3d-s2_group_0.1");
  const auto family = *bench::worldFamily("small-loop");
  for (const auto& c : cases) {
    EXPECT_EQ(c.family, "small-loop");
    EXPECT_EQ(c.information_scale, bench::familyInformationScale(family, 2));
    EXPECT_TRUE(fs::exists(c.base_file)) << c.base_file;
    EXPECT_TRUE(fs::exists(c.file)) << c.file;
    // round(0.1 · closures) false closures, half to even.
    const auto base = bench::loadDataset(c.base_file);
    const int loops =
        std::visit([](const auto& g) { return sim::countLoopClosures(g); }, base.graph);
    EXPECT_EQ(readLabelsFile(c.labels).size(),
              static_cast<size_t>(sim::falseClosureCount(0.1, loops)));
  }
  // The world written is the one `arbor generate small-loop --dim 2 --seed 2
  // --information-scale X` makes: the same number of edges as the generator's in memory.
  const auto world = sim::roadWorld2(bench::familyWorldOptions(family, 2));
  const auto read = std::get<PoseGraph2>(bench::loadDataset(cases[0].base_file).graph);
  EXPECT_EQ(read.numEdges(), world.graph.numEdges());

  plan.families = {"bicycle"};
  EXPECT_THROW(bench::generateFamilyCases(plan, out.string()), std::invalid_argument);
  plan.families = {"small-loop"};
  plan.dims = {4};
  EXPECT_THROW(bench::generateFamilyCases(plan, out.string()), std::invalid_argument);

  // An oracle replay (the clean optimum, exactly the labels rejected) solves the 2D case; F* is
  // the clean optimum the bench found, there being no optimum.tsv row for a family world.
  std::vector<bench::RobustCase> two_d = {cases[0]};
  const bench::CleanReference<SE2> ref = bench::cleanReference(read, std::nan(""));
  bench::RobustReplayHooks hooks;
  hooks.robust2 = [&](const PoseGraph2& g) {
    bench::RobustEstimate<SE2> e;
    e.poses = bench::posesByIds(read, ref.optimum, g);
    e.rejected.assign(g.edges.size(), 0);
    for (int k = read.numEdges(); k < g.numEdges(); ++k) e.rejected[k] = 1;
    return e;
  };
  bench::RobustBatchSettings from_file;
  from_file.start = bench::BatchStart::kFile;
  const auto rows = bench::runRobustBench(two_d, {}, {}, from_file, hooks, nullptr);
  ASSERT_EQ(rows.size(), 1u);
  ASSERT_TRUE(rows[0].error.empty()) << rows[0].error;
  EXPECT_TRUE(std::isfinite(rows[0].F_star));
  EXPECT_EQ(rows[0].F_star, rows[0].F_reference);
  EXPECT_TRUE(std::isfinite(rows[0].closure_chi2_median));
  EXPECT_GE(rows[0].closure_chi2_max, rows[0].closure_chi2_median);
  ASSERT_TRUE(rows[0].replay.has_value());
  EXPECT_TRUE(bench::solved(*rows[0].replay));
  EXPECT_NEAR(rows[0].replay->F_ratio, 1.0, 1e-3);
  const std::string md = bench::familyMarkdown(rows);
  EXPECT_NE(md.find("| small-loop-2d-s2_group_0.1 |"), std::string::npos) << md;
  const std::string batch = bench::solved(rows[0].batch) ? "1" : "0";
  EXPECT_NE(md.find("| small-loop | 2D | 10% | 1 | 1 | " + batch + " | yes |"), std::string::npos)
      << md;
  EXPECT_NE(md.find("`arbor generate small-loop --dim 2 --seed 2 --information-scale "),
            std::string::npos)
      << md;
  fs::remove_all(out);
}

// --ablate: every rule by a name of its own, with its field and property; the rule's field is
// switched off and the other options given stay (the end-word rule's effect on the replay is
// tests/kept_at_word_test.cc's).
TEST(Ablation, EveryRuleHasANameAPropertyAndSwitchesItsFieldOff) {
  std::set<std::string> names;
  for (const bench::Ablation& a : bench::ablations()) {
    EXPECT_FALSE(a.property.empty()) << a.name;
    EXPECT_NE(a.field.find('='), std::string::npos) << a.name;
    EXPECT_TRUE(names.insert(a.name).second) << "twice: " << a.name;
    EXPECT_NO_THROW(bench::ablated(a.name));
  }
  // Every rule of the robust layer is there (issue 52's budget: at most 8), and no other.
  EXPECT_EQ(names.size(), robustRules().size() + 2);  // + corroboration, estimated-scale
  EXPECT_LE(names.size(), 8u);
  for (RobustRule r : robustRules()) {
    EXPECT_TRUE(names.count(toString(r))) << toString(r);
    EXPECT_FALSE(bench::ablated(toString(r)).on(r)) << toString(r);
  }
  EXPECT_FALSE(bench::ablated("end-word").on(RobustRule::kEndWord));
  EXPECT_FALSE(bench::ablated("final-confirm").on(RobustRule::kFinalConfirm));
  EXPECT_EQ(bench::ablated("estimated-scale").scale, NoiseScale::kGiven);
  EXPECT_EQ(bench::ablated("corroboration").corroboration_window, 0);
  // The options given stay but for the rule: an ablation composes with a kernel or another rule.
  RobustOptions o;
  o.finalize_rounds = 3;
  EXPECT_EQ(bench::ablated("end-word", o).finalize_rounds, 3);
  try {
    bench::ablated("no-such-rule");
    ADD_FAILURE() << "no throw";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("'no-such-rule'"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("end-word"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace arbor
