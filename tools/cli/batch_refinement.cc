#include "arbor_slam/tools/cli/batch_refinement.h"

#include <iomanip>
#include <sstream>
#include <stdexcept>

#include "arbor_slam/bayestree/online_smoother.h"
#include "arbor_slam/tools/cli/cli_common.h"

namespace arbor::cli {

nlohmann::json batchRunJson(const BatchRun& b) {
  nlohmann::json j = {{"update", b.update},
                      {"poses", b.poses},
                      {"edges", b.edges},
                      {"F_incremental", b.F_incremental},
                      {"F_batch", b.F_batch},
                      {"relative_gap", b.relative_gap},
                      {"max_translation_diff", b.max_translation_diff},
                      {"max_rotation_diff", b.max_rotation_diff},
                      {"F_lm", b.F_lm},
                      {"winner", b.winner},
                      {"margin", b.margin},
                      {"margin_relative", b.margin_relative},
                      {"time_s", b.time_s},
                      {"lm_time_s", b.lm_time_s},
                      {"iterations", b.iterations},
                      {"updates_during", b.updates_during},
                      {"final", b.final_run},
                      {"reseeded", b.reseeded},
                      {"reseed_s", b.reseed_s}};
  if (b.reseed_rejected) j["reseed_rejected"] = true;
  if (b.cancelled) j["cancelled"] = true;
  if ((b.reseeded || b.reseed_rejected) && !b.final_run) {
    j["F_before_reseed"] = b.F_before_reseed;
    j["F_after_reseed"] = b.F_after_reseed;
  }
  if (b.robust) {  // the F_* above are Σρ
    j["robust"] = true;
    j["judged"] = b.judged;
    j["rejected"] = b.rejected;
    j["inlier_threshold"] = b.threshold;
    if (!b.rtr_skipped.empty()) j["rtr_skipped"] = b.rtr_skipped;
  }
  if (b.rank > 0) {
    j["F_rtr"] = b.F_rtr;
    j["rtr_time_s"] = b.rtr_time_s;
    j["rank"] = b.rank;
    j["lambda_min"] = b.lambda_min;
    j["certified"] = b.certified;
  }
  return j;
}

std::string batchRunLine(const BatchRun& b) {
  std::ostringstream out;
  out << std::setprecision(8) << (b.final_run ? "final" : "update ")
      << (b.final_run ? "" : std::to_string(b.update)) << ": " << b.poses << " poses, " << b.edges
      << " edges, " << (b.robust ? "Σρ inc " : "F inc ") << b.F_incremental
      << (b.robust ? " gnc " : " lm ") << b.F_lm;
  if (b.rank > 0) out << " rtr " << b.F_rtr;
  out << std::setprecision(3) << " (gap " << 100.0 * b.relative_gap << " %, " << b.winner
      << " wins by " << b.margin << " = " << 100.0 * b.margin_relative << " %), max diff "
      << b.max_translation_diff << " m / " << b.max_rotation_diff << " rad, " << b.time_s << " s, "
      << b.updates_during << " updates meanwhile";
  if (b.rank > 0) {
    out << ", rank " << b.rank << " lambda_min " << b.lambda_min
        << (b.certified ? " certified" : " not certified");
  }
  if (b.robust) {
    out << ", " << b.rejected << " of " << b.judged << " judged edges rejected";
    if (!b.rtr_skipped.empty()) out << ", rtr skipped: " << b.rtr_skipped;
  }
  if (b.reseeded) out << ", reseeded (" << b.reseed_s << " s)";
  if (b.reseed_rejected) {
    out << ", rebuild not kept (F " << b.F_after_reseed << " vs " << b.F_before_reseed << ")";
  }
  return out.str();
}

template <class G>
LoopResult<G> runReplayWithBatches(const PoseGraph<G>& graph, const ReplaySettings& settings,
                                   const BatchLoopSettings& loop) {
  refine::RefinerOptions refiner_options;
  refiner_options.solver = loop.solver;
  refiner_options.every = loop.every;
  refiner_options.reseed = loop.reseed;
  refiner_options.synchronous = loop.synchronous;
  refine::BatchRefiner<G> refiner(refiner_options);  // throws on every < 0
  OnlineSmootherOptions<G> options;
  options.smoother = settings.smoother;
  options.robust = settings.robust;  // the batches are robust with it (tools/refine)
  OnlineSmoother<G> smoother(options);
  LoopResult<G> result;

  auto record = [&](const std::vector<BatchRun>& runs, UpdateRow* row) {
    for (const BatchRun& run : runs) {
      if (row) row->latency_ms += 1e3 * run.reseed_s;  // a rebuild, kept or not
      result.batches.push_back(run);
    }
  };
  std::int64_t updates = 0;
  ReplayHooks<G> hooks;
  // Collecting, reseeding and snapshotting happen between updates on this thread: their time is
  // not in the update's latency except a reseed's rebuild, which is added to it.
  hooks.after_update = [&](OnlineSmoother<G>& sm, UpdateRow& row) {
    record(refiner.afterUpdate(sm, ++updates), &row);
  };
  // The batch still in flight at the end of the stream.
  hooks.after_stream = [&](OnlineSmoother<G>& sm) {
    if (auto last = refiner.collect(true)) {
      refiner.reseed(sm, &*last, updates);
      record({last->run}, nullptr);
    }
  };
  result.replay = replayInto(graph, settings, smoother, hooks);
  ReplayResult<G>& r = result.replay;
  result.skipped = refiner.skipped();
  result.reseeds = refiner.reseeds();
  result.reseed_s = refiner.reseedSeconds();

  SnapshotJudgement judgement;
  const PoseGraph<G> snapshot = smoother.snapshot(&judgement);
  if (loop.final_run && snapshot.numPoses() > 1 && snapshot.numEdges() > 0) {
    // Robust: from the finalized smoother's classification, as `arbor batch --robust` starts
    // from the replay's; with --no-finalize as the periodic batches (refine::robustStartOf).
    const OnlineGnc<G>* gnc = smoother.gnc();
    refine::BatchOutcome<G> last =
        gnc ? refine::solveRobustSnapshot(loop.solver, snapshot, judgement.judged,
                                          refine::gncOptionsOf(*gnc, judgement.kernels),
                                          refine::robustStartOf(smoother, judgement.held_out))
            : refine::solveSnapshot(loop.solver, snapshot);
    last.run.update = static_cast<std::int64_t>(r.rows.size());
    last.run.final_run = true;
    auto toGraphOrder = [&](const std::vector<G>& poses) {
      std::vector<G> out = graph.poses;
      for (size_t k = 0; k < poses.size(); ++k) out[graph.index.at(snapshot.ids[k])] = poses[k];
      return out;
    };
    r.batch_poses = toGraphOrder(last.batch);
    r.batch.F_initial = last.run.F_incremental;
    // Robust: F over the edges the online smoother kept, as runReplay's final batch reports.
    r.batch.F_final = settings.robust
                          ? objective(keepEdges(graph, keptEdges(graph, r.closures)), r.batch_poses)
                          : objective(graph, r.batch_poses);
    r.batch.time_s = last.run.time_s;
    r.batch.iterations = last.run.iterations;
    r.batch.termination = Termination::kConverged;
    if (loop.reseed && !last.best.empty()) {  // the final estimate is the best one
      r.poses = toGraphOrder(last.best);
      r.F_final = objective(graph, r.poses);
      last.run.reseeded = true;
      last.run.reseed_update = last.run.update;
    }
    result.batches.push_back(last.run);
  }
  return result;
}

template LoopResult<SE2> runReplayWithBatches(const PoseGraph<SE2>&, const ReplaySettings&,
                                              const BatchLoopSettings&);
template LoopResult<SE3> runReplayWithBatches(const PoseGraph<SE3>&, const ReplaySettings&,
                                              const BatchLoopSettings&);

}  // namespace arbor::cli
