// The robust batch from an online smoother's classification, shared by `arbor batch --robust
// --init online` (tools/cli/online_threshold.h, the classification of a whole replay) and the
// robust batch refinement beside the smoother in `arbor replay` and `arbor serve`
// (batch_refiner.h, the classification of a snapshot): GNC (core/gnc_solver.h) with the closures
// the online smoother rejects held out as known outliers (GNC's graduation from a nearly convex
// start would let them back in), at the bound up to which the smoother keeps a settled inlier
// (robust_constants::kRecheckMargin × its c² in use; GNC-TLS has no hysteresis: at the c² in use
// it rejected true closures the smoother keeps, intel_random_0.1 2 of 785), the closures the
// smoother keeps beyond that bound held at weight 1 (its end backed them; its judgement, not
// GNC's to undo); then readmitFitting takes back each held-out closure the refined estimate fits
// within the bound the smoother's end took closures back within (OnlineStats::
// closure_threshold_at_end, capped by the c² in use): the smoother's hysteresis at both ends.
// Within the c² in use instead, sphere_bignoise_vertex3_random_0.1 took back eight false closures
// the replay's end had dropped (F_clean 1.0135 F* against the replay's 1.0090).
#pragma once

#include <vector>

#include "arbor_slam/core/gnc_solver.h"
#include "arbor_slam/core/pose_graph.h"

namespace arbor::refine {

/// How an online smoother holds a graph's edges (per edge, in the graph's order).
struct OnlineClassification {
  /// A loop closure the smoother does not hold as a settled inlier (rejected; mid-stream also
  /// one still graduating or held in the warm-up): a known outlier for GNC
  /// (GncOptions::known_outliers), which readmitFitting may take back. Empty: none.
  std::vector<char> held_out;
  /// GNC's c²: recheck_margin × the smoother's c² in use. ≤ 0: GncOptions::threshold as given,
  /// and no closure is held at weight 1.
  double c2 = 0;
  /// readmitFitting's bound (OnlineThreshold::c2_take_back). ≤ 0: GNC's c².
  double c2_take_back = 0;
};

/// The bounds of `online` (header comment) from the smoother's c² in use, the c² its finalize()
/// judged by (0: finalize() has not run) and recheck_margin.
OnlineClassification onlineBounds(double c2_in_use, double c2_at_end, double recheck_margin);

struct GncFromOnline {
  GncResult gnc;
  int known_outliers = 0;  ///< closures the smoother rejects, held out of GNC
  int readmitted = 0;      ///< of them, taken back by readmitFitting
  /// Closures the smoother keeps with s above OnlineClassification::c2 at *poses, held as
  /// trusted edges.
  int kept_beyond = 0;
};

/// GNC from *poses (the smoother's estimate) as the header comment says; `options` as for
/// solveGnc (its trusted edges are never held out); the estimate is written to *poses. Throws
/// std::invalid_argument when `online.held_out` is neither empty nor one mark per edge.
template <class G>
GncFromOnline solveGncFromOnline(const PoseGraph<G>& graph, GncOptions options,
                                 const OnlineClassification& online, std::vector<G>* poses);

}  // namespace arbor::refine
