// The robust batch's threshold from the online estimator (`arbor batch --robust
// --inlier-threshold online`): the graph's edges replayed through the robust online smoother
// (bayestree/online_gnc.h, its defaults: innovation entry test, estimated noise scale, warm-up
// held), and GNC's c² the bound up to which that smoother keeps a settled inlier at its end:
// recheck_margin (2) times its c² in use, tail_factor·c²_χ²·σ̂² (or the χ² quantile when it has
// no estimate). GNC-TLS has no such hysteresis: at the c² in use itself it rejected true
// closures the online smoother keeps (intel_random_0.1: 2 of 785, F 10.7% above F*; the
// garage: 11 of 4615, 3%; docs/benchmarks.md). The files' Ω are often wrong by a constant
// factor (the shared 2D files' 40–50× too weak, the garage's ~10⁴): the χ² quantile at Ω's word
// keeps their false closures, and σ̂² is what the replay measures from its closures'
// innovations.
#pragma once

#include <vector>

#include "arbor_slam/core/gnc_solver.h"
#include "arbor_slam/core/pose_graph.h"
#include "arbor_slam/core/robust_kernel.h"
#include "arbor_slam/io/edge_choice_file.h"
#include "arbor_slam/tools/refine/gnc_from_online.h"

namespace arbor::cli {

struct OnlineThreshold {
  double c2 = 0;         ///< GNC's: recheck_margin · c2_in_use
  double c2_in_use = 0;  ///< the online smoother's c² in use at the end of the replay
  /// What its finalize() took a rejected closure back within: the end's scale where it stood
  /// (RobustRule::kEndScale, OnlineStats::closure_threshold_at_end), else c2_in_use
  double c2_take_back = 0;
  double noise_scale = 1;  ///< its σ̂²
  bool estimated = false;  ///< σ̂² is an estimate (false: Ω at its word)
  int samples = 0;         ///< innovations it was estimated from
  double replay_s = 0;     ///< wall time of the replay
  /// Per edge of the graph: the replay kept it (false: a loop closure it rejected).
  std::vector<char> kept;
};

/// Replays `graph` (edges in order of max(i, j), one update each, then finalize()) through the
/// robust online smoother with `kernel` and `choices` and returns its threshold; `estimate`
/// (optional): its estimate, in the graph's dense order (`arbor batch --init online`).
template <class G>
OnlineThreshold onlineThreshold(const PoseGraph<G>& graph, KernelKind kernel,
                                const EdgeChoices& choices, std::vector<G>* estimate = nullptr);

/// The robust batch from the online replay (`arbor batch --robust --init online`): the replay
/// (onlineThreshold, its estimate the start), then refine::solveGncFromOnline
/// (tools/refine/gnc_from_online.h) from its classification: with `online_threshold` at the
/// replay's bounds (OnlineThreshold::c2, c2_take_back), without it at GNC's c² (`options`). The
/// estimate is written to *poses. The GNC's figures are refine::GncFromOnline's (kept_beyond:
/// the closures the replay's end backed beyond OnlineThreshold::c2, with `online_threshold`).
struct OnlineBatch : refine::GncFromOnline {
  OnlineThreshold online;
};
template <class G>
OnlineBatch solveGncFromReplay(const PoseGraph<G>& graph, GncOptions options,
                               const EdgeChoices& choices, bool online_threshold,
                               std::vector<G>* poses);

}  // namespace arbor::cli
