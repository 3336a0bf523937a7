// Batch refinement in the replay loop (issue 5, "The loop"): every N updates the poses known so
// far, the edges accepted so far and the incremental estimate are snapshotted and solved by
// batch LM (from the incremental estimate) or SE-Sync RTR in a background thread while edges keep
// flowing; at most one batch is in flight. With reseeding, a batch estimate that beats the
// incremental one on its snapshot rebuilds the smoother from it between two updates.
//
// The replay here drives an IncrementalSmoother directly with the online layer's rules (the
// first pose seen is fixed at the identity; an edge to an unknown pose creates it from the known
// end composed with the measurement or its inverse; edges between two unknown poses are held
// until one end is known; identical repeated edges are dropped) because OnlineSmoother cannot be
// given initial values for known poses.
#pragma once

#include <string>
#include <vector>

#include "tools/cli/replay_runner.h"

namespace arbor::cli {

enum class BatchKind { kLm, kRtr };
/// "lm" or "rtr"; throws std::invalid_argument naming the value.
BatchKind parseBatchKind(const std::string& name);
std::string toString(BatchKind kind);

struct BatchLoopSettings {
  BatchKind kind = BatchKind::kLm;
  int every = 0;          ///< a background batch every this many updates (0: only the final one)
  bool reseed = false;    ///< rebuild the smoother from a batch estimate that beats it
  bool final_run = true;  ///< a last (synchronous) batch run on the complete graph
  /// Poses added since the reseeding snapshot start at their creator's new value composed with
  /// their current incremental estimate relative to the creator (true), or with the creating
  /// edge's measurement as the online layer does (false: dead reckoning, which can be far off
  /// when many poses arrived while the batch ran).
  bool reseed_relative = true;
  /// Run each batch on the replay thread right at its snapshot (blocking; deterministic, for
  /// tests and reproducible comparisons) instead of in the background.
  bool synchronous = false;
};

/// One batch run on a snapshot.
struct BatchRun {
  int update = 0;  ///< updates applied when the snapshot was taken
  int poses = 0, edges = 0;
  double F_incremental = 0;  ///< of the incremental estimate on the snapshot
  double F_batch = 0;
  double relative_gap = 0;  ///< (F_incremental − F_batch) / F_batch
  /// Largest per-pose difference between the two estimates, both expressed in the frame of
  /// their first pose: translation (‖·‖) and rotation angle (radians).
  double max_translation_diff = 0, max_rotation_diff = 0;
  std::string winner;      ///< "batch", "incremental" or "tie" (|ΔF| ≤ 1e-9 F)
  double margin = 0;       ///< |F_incremental − F_batch|
  double time_s = 0;       ///< the solve's wall time
  int iterations = 0;      ///< LM iterations, or RTR trust-region iterations
  int updates_during = 0;  ///< updates applied while it ran in the background
  bool final_run = false;  ///< the run on the complete graph after finalize
  bool reseeded = false;   ///< the smoother was rebuilt from it
  double reseed_s = 0;     ///< time of that rebuild (part of that update's latency)
  /// F of the smoother over everything it holds just before and after the rebuild.
  double F_before_reseed = 0, F_after_reseed = 0;
  int reseed_update = 0;  ///< the update whose latency includes the rebuild
  // RTR only:
  int rank = 0;
  double lambda_min = 0;
  bool certified = false;
};

template <class G>
struct LoopResult {
  ReplayResult<G> replay;  ///< as runReplay (batch = the final run when settings.final_run)
  std::vector<BatchRun> batches;
  int skipped = 0;  ///< due snapshots skipped because a batch was still running
  int reseeds = 0;
  double reseed_s = 0;  ///< summed rebuild time
};

/// Replays `graph` as runReplay does (settings.batch is ignored: see loop.final_run) with batch
/// runs per `loop`. Throws std::invalid_argument on loop.every < 0.
template <class G>
LoopResult<G> runReplayWithBatches(const PoseGraph<G>& graph, const ReplaySettings& settings,
                                   const BatchLoopSettings& loop);

}  // namespace arbor::cli
