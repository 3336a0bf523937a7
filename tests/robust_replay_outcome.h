// Test helper: a robust replay (`arbor replay --robust`'s runner) of a graph, and what it ended
// with: the rejected closures, the counters and F over a clean graph's edges at its estimate.
#pragma once

#include <algorithm>
#include <set>
#include <utility>
#include <vector>

#include "arbor_slam/bayestree/online_gnc.h"
#include "arbor_slam/core/pose_graph.h"
#include "arbor_slam/tools/cli/replay_runner.h"

namespace arbor::testing {

struct RobustOutcome {
  std::set<std::pair<Key, Key>> rejected;  ///< (from, to), low id first
  int unconfirmed = 0;                     ///< OnlineStats::closures_unconfirmed
  int rechecks_bounded = 0;                ///< OnlineStats::rechecks_bounded
  double F_clean = 0;                      ///< F over `clean`'s edges at the estimate
  double c2 = 0, c2_end = 0;    ///< OnlineStats::closure_threshold and closure_threshold_at_end
  int finalize_iterations = 0;  ///< ReplayResult::finalize_iterations
};

/// The closures a replay ended rejecting, as (from, to) with the low id first.
inline std::set<std::pair<Key, Key>> rejectedPairs(const std::vector<ClosureReport>& closures) {
  std::set<std::pair<Key, Key>> out;
  for (const ClosureReport& c : closures)
    if (c.status == ClosureStatus::kOutlier)
      out.insert({std::min(c.from, c.to), std::max(c.from, c.to)});
  return out;
}

/// F over `graph`'s edges at its plain replay's estimate (`arbor replay` without --robust and
/// without its batch LM): the clean optimum the robust replays are compared with.
template <class G>
double plainReplayF(const PoseGraph<G>& graph) {
  cli::ReplaySettings plain;
  plain.batch = false;
  return objective(graph, cli::runReplay(graph, plain).poses);
}

/// `graph` replayed with `robust` (no batch); F_clean over `clean` (same poses, same order).
template <class G>
RobustOutcome replayRobust(const PoseGraph<G>& clean, const PoseGraph<G>& graph,
                           const RobustOptions& robust) {
  cli::ReplaySettings settings;
  settings.robust = robust;
  settings.batch = false;
  const cli::ReplayResult<G> r = cli::runReplay(graph, settings);
  RobustOutcome out;
  out.rejected = rejectedPairs(r.closures);
  out.unconfirmed = r.online.closures_unconfirmed;
  out.rechecks_bounded = r.online.rechecks_bounded;
  out.F_clean = objective(clean, r.poses);
  out.c2 = r.online.closure_threshold;
  out.c2_end = r.online.closure_threshold_at_end;
  out.finalize_iterations = r.finalize_iterations;
  return out;
}

}  // namespace arbor::testing
