// Batch refinement beside the incremental smoother (issue 5, "The loop"), shared by `arbor
// replay` and `arbor serve`: a snapshot of the OnlineSmoother (poses and edges of the last
// update, the incremental estimate) is solved by batch LM from the incremental estimate or by
// the certifiable SE-Sync solver (RTR, LM-polished) in a background thread while updates go on;
// the owner polls for the result between updates; at most one batch is in flight.
//
// Keep-best: SE-Sync certifies its isotropic-weight relaxation, not our F (on strongly
// anisotropic Ω its polished answer can end far above the best F), so an RTR run also runs
// plain LM from the incremental estimate on the same snapshot and the lowest F of incremental,
// LM and RTR wins; the report says which and by how much. With reseeding, a winning batch
// estimate becomes the smoother's linearisation point (OnlineSmoother::reseed).
//
// Robust (the smoother has online robust smoothing, OnlineSmootherOptions::robust): the batch is
// GNC (core/gnc_solver.h, the smoother's kernel, each closure's own kernel) from the incremental
// estimate over the snapshot, trusting exactly the edges the online GNC trusts. Before
// finalize() (the periodic batches) it is a correction: every judged closure graduates afresh at
// the c² in use, the smoother's classification being provisional. Once the smoother is
// finalized (OnlineSmoother::finalized: the replay's final batch, a batch asked for after
// finalize()) it starts from that classification as `arbor batch --robust --init online` starts
// from the replay's (gnc_from_online.h: what the smoother does not hold as settled inliers held
// out, GNC at the bound it keeps a settled inlier within, taken back within its end's bound).
// For rtr then SE-Sync's staircase on GNC's inlier set (certifyInliers, taking back within the
// same bound: the certificate is of the inlier problem, not of the choice of inliers). Each
// choice measured against the other (docs/benchmarks.md, "Robust batches in the loop"): every
// closure free in the final batch took sphere_bignoise_vertex3_random_0.1 to 1.179 F* over the
// clean edges (1.009 without the loop); held out in the periodic batches (every 100 updates,
// reseeding), smallGrid3D group 0.5 seed 2 went to 25 F*. Keep-best compares Σρ (the
// robust cost: ρ of the judged edges, TLS min(s, c²), eᵀΩe of the others) instead of F, since F
// counts the false closures in full; the report's F_* fields then hold Σρ and the winner is
// "incremental", "gnc" or "rtr". A reseed carries the classification through the values:
// OnlineSmoother::reseed keeps the rebuild only if it lowers Σρ and re-checks every settled closure
// at the new point.
//
// Thread-safety: a BatchRefiner belongs to the thread that owns the smoother; only the solve of
// a snapshot (a copy) runs on the background thread.
#pragma once

#include <cstdint>
#include <limits>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "arbor_slam/bayestree/online_smoother.h"
#include "arbor_slam/core/gnc_solver.h"
#include "arbor_slam/core/pose_graph.h"
#include "arbor_slam/tools/refine/batch_solvers.h"
#include "arbor_slam/tools/refine/gnc_from_online.h"

namespace arbor::refine {

struct RefinerOptions {
  /// A row of batchSolvers() marked `refines` (lm, rtr).
  BatchSolver solver = BatchSolver::kLevenbergMarquardt;
  int every = 0;        ///< a batch every this many updates (0: only when asked)
  bool reseed = false;  ///< a winning batch estimate becomes the linearisation point
  /// Solve on the calling thread inside start() (blocking; deterministic, for tests and
  /// reproducible comparisons) instead of in the background.
  bool synchronous = false;
  /// Every batch the refiner runs checks this token (copies share it): cancel() stops the
  /// batch in flight at its next iteration and every batch started later at its first (a
  /// service that is stopping). Thread-safe; the run is then marked cancelled.
  CancellationToken cancel = {};
};

/// One batch run on a snapshot.
struct BatchRun {
  std::int64_t update = 0;  ///< updates applied when the snapshot was taken
  int poses = 0, edges = 0;
  double F_incremental = 0;  ///< of the incremental estimate on the snapshot
  double F_batch = 0;        ///< of the --batch solver's estimate (RTR's for rtr)
  double relative_gap = 0;   ///< (F_incremental − F_batch) / F_batch
  /// Largest per-pose difference between the incremental and the batch estimate, both in the
  /// frame of their first pose: translation (‖·‖) and rotation angle (radians).
  double max_translation_diff = 0, max_rotation_diff = 0;
  double F_lm = 0;  ///< plain LM from the incremental estimate (= F_batch for lm)
  double F_rtr = std::numeric_limits<double>::quiet_NaN();  ///< RTR + polish (rtr only)
  /// Lowest F of "incremental", "lm" and (for rtr) "rtr"; a batch estimate must beat the
  /// incremental one by more than 1e-9 relative to win.
  std::string winner;
  double margin = 0;           ///< |F of the runner-up − F of the winner|
  double margin_relative = 0;  ///< margin / F of the winner
  double time_s = 0;           ///< wall time of the solves (RTR + LM for rtr)
  double lm_time_s = 0, rtr_time_s = 0;
  int iterations = 0;      ///< of the --batch solver: LM iterations or RTR trust-region iterations
  int updates_during = 0;  ///< updates applied while it ran in the background
  bool final_run = false;  ///< replay: the run on the complete graph after finalize
  /// Stopped by RefinerOptions::cancel: its figures are of the iterates so far, and it has no
  /// winner estimate to reseed from (BatchOutcome::best is empty).
  bool cancelled = false;
  bool reseeded = false;  ///< the smoother was rebuilt from the winner's estimate
  /// A rebuild was tried but not kept: over everything the smoother holds by then (poses and
  /// edges that came after the snapshot included) it did not lower F.
  bool reseed_rejected = false;
  double reseed_s = 0;  ///< time of that rebuild, kept or not (part of that update's latency)
  /// F of the smoother over everything it holds just before and after the rebuild (after: of
  /// the rebuilt one, also when it was not kept).
  double F_before_reseed = 0, F_after_reseed = 0;
  std::int64_t reseed_update = 0;  ///< the update after which the rebuild ran
  // RTR only:
  int rank = 0;
  double lambda_min = 0;
  bool certified = false;
  // Robust (header comment): F_incremental, F_lm (GNC's), F_rtr and F_batch are Σρ.
  bool robust = false;
  int judged = 0;    ///< snapshot edges GNC weighted (the others trusted)
  int rejected = 0;  ///< of them, outliers in the batch estimate (--batch's solver)
  /// GNC's c² on eᵀΩe (recheck_margin × the online smoother's c² in use; Σρ is at the c² in use)
  double threshold = 0;
  /// rtr: why the staircase did not run on the inlier set ("" when it did), e.g. priors.
  std::string rtr_skipped;
};

struct Verdict {
  std::string winner;  ///< "incremental", "lm" or "rtr"
  double margin = 0;   ///< |F of the runner-up − F of the winner|
  double margin_relative = 0;
};
/// Keep-best among the incremental, the LM and the RTR estimate (F_rtr NaN: not run): the lowest
/// F, except that a batch estimate must beat the incremental one by more than 1e-9 relative to
/// win; LM and RTR tie in favour of RTR.
Verdict pickWinner(double F_incremental, double F_lm, double F_rtr);

template <class G>
struct BatchOutcome {
  BatchRun run;
  std::vector<G> batch;  ///< the --batch solver's estimate of the snapshot's poses (dense order)
  std::vector<G> best;   ///< the winner's estimate; empty when the incremental one won
  std::vector<G> incremental;  ///< the snapshot's incremental estimate (its poses)
};

/// Solves `snapshot` (its poses: the incremental estimate; gauge = its first fixed pose) and
/// fills every figure of the run except the loop's (update, updates_during, reseed fields).
/// The solves check `cancel`. Any thread. Throws std::invalid_argument for a solver whose row
/// does not refine, and what the solvers throw.
template <class G>
BatchOutcome<G> solveSnapshot(BatchSolver solver, const PoseGraph<G>& snapshot,
                              const CancellationToken& cancel = {});

/// The robust batch of a snapshot (header comment): solveGncFromOnline (gnc_from_online.h) with
/// `gnc` (its kernel and per-edge kernels; `judged` per edge: weighted, else trusted) from the
/// smoother's classification `online` (what it does not hold as settled inliers held out, GNC at
/// its bound, taken back within its end's; default: every closure free, GNC at gnc.threshold, the
/// periodic batches'), then for rtr certifyInliers taking back within the same bound; keep-best by
/// Σρ at gnc.threshold. Every solve checks gnc.cancel; a cancelled run is marked and has no winner
/// estimate.
template <class G>
BatchOutcome<G> solveRobustSnapshot(BatchSolver solver, const PoseGraph<G>& snapshot,
                                    const std::vector<char>& judged, GncOptions gnc,
                                    const OnlineClassification& online = {});

/// The GNC options of a robust batch beside `online`: its kernel and threshold c² (the c² in
/// use), and `kernels` (per snapshot edge, OnlineSmoother::snapshot) as GncOptions::kernels, so
/// that each closure graduates towards the kernel the online GNC judges it by.
template <class G>
GncOptions gncOptionsOf(const OnlineGnc<G>& online, std::vector<KernelKind> kernels = {});

/// What a robust batch of `smoother`'s snapshot starts from (header comment): once the smoother
/// is finalized (OnlineSmoother::finalized), its classification, `held_out`
/// (SnapshotJudgement::held_out) and its bounds (onlineBounds: recheck_margin × the c² in use;
/// the take-back bound of its finalize(), capped by the c² in use); before, nothing held out and
/// GNC at the c² in use (an empty OnlineClassification). Throws std::invalid_argument without
/// robust smoothing.
template <class G>
OnlineClassification robustStartOf(const OnlineSmoother<G>& smoother, std::vector<char> held_out);

/// Σρ of `poses` on `graph`: for the edges marked in `judged` ρ(s) of the edge's kernel
/// (gnc.kernels[e], or gnc.kernel where that is empty or kNone) at c² = gnc.threshold (TLS:
/// min(s, c²)), s = eᵀΩe for every other edge and prior.
template <class G>
double robustCost(const PoseGraph<G>& graph, const std::vector<G>& poses,
                  const std::vector<char>& judged, const GncOptions& gnc);

/// The values a reseed from `outcome` gives the snapshot's poses (the first best.size() in dense
/// order): the winner's correction of the snapshot's incremental estimate applied on the left
/// of the current estimate, x'_k = b_k · s_k⁻¹ · x_k (b: winner, s: incremental at the snapshot,
/// x: now). With no update since the snapshot this is the winner's estimate; when updates went
/// on meanwhile (a background batch) it keeps what they changed instead of overwriting it with
/// a stale value (absolute values of a late batch can raise F far above both estimates:
/// docs/design.md, "Batch refinement in the loop"). Poses created after the snapshot then
/// follow their creator (OnlineSmoother::seedPoint). Throws std::invalid_argument on sizes
/// that do not fit.
template <class G>
std::vector<G> seedValues(const OnlineSmoother<G>& smoother, const BatchOutcome<G>& outcome);

template <class G>
class BatchRefiner {
 public:
  /// Throws std::invalid_argument on options.every < 0 or a solver whose row does not refine.
  explicit BatchRefiner(RefinerOptions options = {});
  ~BatchRefiner();  ///< waits for a batch still running (cancel options.cancel first to cut it)
  BatchRefiner(const BatchRefiner&) = delete;
  BatchRefiner& operator=(const BatchRefiner&) = delete;

  const RefinerOptions& options() const { return options_; }
  /// options.every > 0 and `updates` is a multiple of it.
  bool due(std::int64_t updates) const;
  bool inFlight() const;  ///< started and not yet collected
  bool running() const;   ///< in flight and not finished

  /// Snapshots `smoother` and solves it in the background (or here when synchronous). Returns
  /// false without starting when a batch is in flight (counted in skipped()) or when the
  /// snapshot has fewer than 2 poses.
  /// One background job at a time on the second core (docs/design.md, "Asynchronous
  /// relinearisation"): a due run is skipped and counted while the smoother's background
  /// relinearisation is pending, and while a run is in flight the smoother relinearises inline
  /// (OnlineSmoother::setSecondCoreBusy, cleared by collect).
  bool start(OnlineSmoother<G>& smoother, std::int64_t update);
  /// Counts an update applied while a batch is still running.
  void noteUpdate();
  /// The batch in flight once it has finished (`wait`: waits for it); nullopt if none (or not
  /// finished). Rethrows the solver's exception (the batch is then dropped).
  std::optional<BatchOutcome<G>> collect(bool wait);
  /// With options.reseed and a winning batch estimate: rebuilds `smoother` from it, keeps the
  /// rebuild only if it lowers F over everything the smoother holds, and fills the run's reseed
  /// fields. Returns whether it kept it.
  bool reseed(OnlineSmoother<G>& smoother, BatchOutcome<G>* outcome, std::int64_t update);

  /// The loop's step after update number `updates`: counts it for a running batch, collects a
  /// finished one (reseeding per options), and starts a due one (with synchronous, solves and
  /// collects it at once). Returns the runs finished in this step (0, 1 or 2).
  std::vector<BatchRun> afterUpdate(OnlineSmoother<G>& smoother, std::int64_t updates);

  int completed() const { return completed_; }
  int skipped() const { return skipped_; }
  int reseeds() const { return reseeds_; }
  double reseedSeconds() const { return reseed_s_; }

 private:
  struct Flight;
  RefinerOptions options_;
  std::unique_ptr<Flight> flight_;
  int completed_ = 0, skipped_ = 0, reseeds_ = 0;
  double reseed_s_ = 0;
};

extern template class BatchRefiner<SE2>;
extern template class BatchRefiner<SE3>;

}  // namespace arbor::refine
