// Batch refinement in the replay loop (issue 5, "The loop"): `arbor replay --batch lm|rtr
// --batch-every N [--reseed]` replays a graph through an OnlineSmoother as runReplay does, with
// a refine::BatchRefiner solving snapshots in the background every N updates (keep-best of
// incremental / LM / RTR, optional reseeding), and a last batch run on the complete graph.
#pragma once

#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "arbor_slam/tools/cli/replay_runner.h"
#include "arbor_slam/tools/refine/batch_refiner.h"

namespace arbor::cli {

using refine::BatchRun;
using refine::BatchSolver;

struct BatchLoopSettings {
  /// A row of refine::batchSolvers() marked `refines` (lm, rtr).
  BatchSolver solver = BatchSolver::kLevenbergMarquardt;
  int every = 0;          ///< a background batch every this many updates (0: only the final one)
  bool reseed = false;    ///< rebuild the smoother from a batch estimate that beats it
  bool final_run = true;  ///< a last (synchronous) batch run on the complete graph
  /// Run each batch on the replay thread right at its snapshot (blocking; deterministic, for
  /// tests and reproducible comparisons) instead of in the background.
  bool synchronous = false;
};

template <class G>
struct LoopResult {
  ReplayResult<G> replay;  ///< as runReplay (batch = the final run's when settings.final_run)
  std::vector<BatchRun> batches;
  int skipped = 0;  ///< due snapshots skipped because a batch was still running
  int reseeds = 0;
  double reseed_s = 0;  ///< summed rebuild time
};

/// A run as the JSON object of `batches: [...]` (replay and serve --json).
nlohmann::json batchRunJson(const BatchRun& run);
/// A run as one human-readable line.
std::string batchRunLine(const BatchRun& run);

/// Replays `graph` as runReplay does (settings.batch is ignored: see loop.final_run) with batch
/// runs per `loop`. Throws std::invalid_argument on loop.every < 0 or a solver that does not
/// refine.
template <class G>
LoopResult<G> runReplayWithBatches(const PoseGraph<G>& graph, const ReplaySettings& settings,
                                   const BatchLoopSettings& loop);

}  // namespace arbor::cli
