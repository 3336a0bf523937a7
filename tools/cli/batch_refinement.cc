#include "tools/cli/batch_refinement.h"

#include <iomanip>
#include <numeric>
#include <sstream>
#include <stdexcept>

#include "bayestree/online_smoother.h"
#include "tools/cli/cli_common.h"
#include "tools/cli/replay_order.h"

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
  if ((b.reseeded || b.reseed_rejected) && !b.final_run) {
    j["F_before_reseed"] = b.F_before_reseed;
    j["F_after_reseed"] = b.F_after_reseed;
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
      << " edges, F inc " << b.F_incremental << " lm " << b.F_lm;
  if (b.rank > 0) out << " rtr " << b.F_rtr;
  out << std::setprecision(3) << " (gap " << 100.0 * b.relative_gap << " %, " << b.winner
      << " wins by " << b.margin << " = " << 100.0 * b.margin_relative << " %), max diff "
      << b.max_translation_diff << " m / " << b.max_rotation_diff << " rad, " << b.time_s << " s, "
      << b.updates_during << " updates meanwhile";
  if (b.rank > 0) {
    out << ", rank " << b.rank << " lambda_min " << b.lambda_min
        << (b.certified ? " certified" : " not certified");
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
  refiner_options.kind = loop.kind;
  refiner_options.every = loop.every;
  refiner_options.reseed = loop.reseed;
  refiner_options.synchronous = loop.synchronous;
  refine::BatchRefiner<G> refiner(refiner_options);  // throws on every < 0
  OnlineSmootherOptions<G> options;
  options.smoother = settings.smoother;
  OnlineSmoother<G> smoother(options);
  LoopResult<G> result;
  ReplayResult<G>& r = result.replay;

  auto record = [&](const std::vector<BatchRun>& runs, UpdateRow* row) {
    for (const BatchRun& run : runs) {
      if (row) row->latency_ms += 1e3 * run.reseed_s;  // a rebuild, kept or not
      result.batches.push_back(run);
    }
  };

  const std::vector<std::vector<int>> groups = replayGroups(graph, settings.per_pose);
  r.rows.reserve(groups.size());
  int fed = 0;
  for (const auto& group : groups) {
    for (int e : group) {
      const auto& edge = graph.edges[e];
      const Key from = graph.ids[edge.i], to = graph.ids[edge.j];
      const EdgeResult added = smoother.addEdge(from, to, edge.measurement, edge.information);
      if (added.status == EdgeStatus::kDuplicate) ++r.duplicates;
      if (added.status == EdgeStatus::kRejected) {
        ++r.rejected;
        r.rejections.push_back("edge " + std::to_string(from) + " -> " + std::to_string(to) +
                               " rejected: " + added.reason);
      }
    }
    fed += static_cast<int>(group.size());
    Stopwatch clock;
    const UpdateStats s = smoother.update();
    const double ms = 1e3 * clock.seconds();
    r.relinearized += s.variables_relinearized;
    r.indeterminate += s.indeterminate_cliques;
    r.rows.push_back({static_cast<int>(r.rows.size()) + 1, fed, ms, s.cliques_reeliminated,
                      s.variables_relinearized});
    // Collecting, reseeding and snapshotting happen between updates on this thread: their time
    // is not in the update's latency except a reseed's rebuild, which is added to it.
    record(refiner.afterUpdate(smoother, static_cast<std::int64_t>(r.rows.size())), &r.rows.back());
  }
  // The batch still in flight at the end of the stream.
  if (auto last = refiner.collect(true)) {
    refiner.reseed(smoother, &*last, static_cast<std::int64_t>(r.rows.size()));
    record({last->run}, nullptr);
  }
  result.skipped = refiner.skipped();
  result.reseeds = refiner.reseeds();
  result.reseed_s = refiner.reseedSeconds();

  r.F_incremental = smoother.smoother().objective();
  Stopwatch finalize_clock;
  if (settings.finalize) {
    const UpdateStats s = smoother.finalize();
    r.relinearized += s.variables_relinearized;
    r.indeterminate += s.indeterminate_cliques;
  }
  r.finalize_s = finalize_clock.seconds();
  r.pending = smoother.stats().edges_pending;
  std::vector<double> ms;
  for (const auto& row : r.rows) ms.push_back(row.latency_ms);
  r.latency = summarizeLatency(ms);
  r.update_s = std::accumulate(ms.begin(), ms.end(), 0.0) / 1e3;
  r.total_s = r.update_s + r.finalize_s;
  // The estimate in the graph's dense order (poses never reached keep their graph value).
  r.poses = graph.poses;
  for (const auto& [id, pose] : smoother.estimates()) r.poses[graph.index.at(id)] = pose;
  r.F_final = objective(graph, r.poses);

  const PoseGraph<G> snapshot = smoother.snapshot();
  if (loop.final_run && snapshot.numPoses() > 1 && snapshot.numEdges() > 0) {
    refine::BatchOutcome<G> last = refine::solveSnapshot(loop.kind, snapshot);
    last.run.update = static_cast<std::int64_t>(r.rows.size());
    last.run.final_run = true;
    auto toGraphOrder = [&](const std::vector<G>& poses) {
      std::vector<G> out = graph.poses;
      for (size_t k = 0; k < poses.size(); ++k) out[graph.index.at(snapshot.ids[k])] = poses[k];
      return out;
    };
    r.batch_poses = toGraphOrder(last.batch);
    r.batch.F_initial = last.run.F_incremental;
    r.batch.F_final = objective(graph, r.batch_poses);
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
