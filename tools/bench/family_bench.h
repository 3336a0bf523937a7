// Issue 52's held-out protocol in `arbor bench robust --family NAMES --seeds A-B`: the worlds
// of each family (tools/bench/world_families.h) × dimension × seed, each with false closures
// planted at every fraction × policy, run through runRobustBench (robust_bench.h: the robust
// replay and the robust batch with their defaults, judged against the world's clean optimum),
// and reported one row per case plus a summary per family × dimension × fraction.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "arbor_slam/tools/bench/robust_bench.h"
#include "arbor_slam/tools/generator/false_closures.h"

namespace arbor::bench {

/// What the protocol generates: every family × dimension × seed, each world with every
/// fraction × policy.
struct FamilyPlan {
  std::vector<std::string> families;  ///< world_families.h's names
  std::vector<int> dims = {2, 3};
  std::vector<double> fractions = {0.1, 0.5, 0.9};
  std::vector<sim::OutlierPolicy> policies = {
      sim::OutlierPolicy::kRandom, sim::OutlierPolicy::kLocal, sim::OutlierPolicy::kGroup};
  std::vector<std::uint64_t> seeds = {1, 2, 3};
};

/// Writes each world of `plan` (OUT_DIR/NAME.g2o, NAME = familyWorldName) and its planted
/// files (NAME_P_F.g2o and .labels) and returns the cases in the plan's order (family,
/// dimension, seed, fraction, policy), each with its family and X. Throws
/// std::invalid_argument naming the value for an unknown family or a dimension other than 2
/// or 3, FileError when a file cannot be written.
std::vector<RobustCase> generateFamilyCases(const FamilyPlan& plan, const std::string& out_dir);

/// Issue 52's goal covers a case: 10% and 50% false closures in 2D and 3D, 90% in 2D.
bool familyGoalCovers(int dim, double fraction);

/// The protocol's report: one row per case (X, loop closures, false closures, the replay's
/// and the batch's F/F* · P · R, solved by each), then one summary row per family × dimension
/// × fraction (cases the replay and the batch solve, whether the goal covers it), then a line
/// per family: solved of the covered cases, replay and batch.
std::string familyMarkdown(const std::vector<RobustRow>& rows);

}  // namespace arbor::bench
