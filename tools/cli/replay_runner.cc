#include "arbor_slam/tools/cli/replay_runner.h"

#include <fstream>
#include <iomanip>
#include <numeric>
#include <set>
#include <stdexcept>

#include "arbor_slam/bayestree/online_smoother.h"
#include "arbor_slam/core/gnc_solver.h"
#include "arbor_slam/tools/cli/cli_common.h"
#include "arbor_slam/tools/cli/peak_rss.h"
#include "arbor_slam/tools/cli/replay_order.h"

namespace arbor::cli {

template <class G>
ReplayResult<G> replayInto(const PoseGraph<G>& graph, const ReplaySettings& settings,
                           OnlineSmoother<G>& smoother, const ReplayHooks<G>& hooks) {
  ReplayResult<G> result;
  std::vector<std::vector<int>> groups = replayGroups(graph, settings.per_pose);
  mergeFirstGroups(&groups, settings.first_update_edges);
  result.rows.reserve(groups.size());
  // A pose's priors are fed right after the edge that makes the pose known (replay_order.h).
  const PriorSchedule schedule(graph);
  std::vector<char> prior_fed(graph.ids.size(), 0);
  auto feed_priors = [&](int pose) {
    if (prior_fed[pose] || !smoother.hasPose(graph.ids[pose])) return;
    prior_fed[pose] = 1;
    for (const PriorRef& p : schedule.of(pose)) {
      const EdgeResult r = feedPrior(graph, p, smoother);
      if (r.status == EdgeStatus::kRejected) {
        ++result.rejected;
        result.rejections.push_back("prior on " + std::to_string(graph.ids[pose]) +
                                    " rejected: " + r.reason);
      }
    }
  };
  int fed = 0;
  for (const auto& group : groups) {
    for (int e : group) {
      const auto& edge = graph.edges[e];
      const Key from = graph.ids[edge.i], to = graph.ids[edge.j];
      const EdgeChoice choice = edgeChoice(settings.choices, from, to);
      if (settings.initial_from_file) {  // kept only for a pose not created yet
        smoother.setInitialGuess(from, graph.poses[edge.i]);
        smoother.setInitialGuess(to, graph.poses[edge.j]);
      }
      const EdgeResult r = smoother.addEdge(from, to, edge.measurement, edge.information,
                                            choice.trust, choice.kernel);
      if (r.status == EdgeStatus::kDuplicate) ++result.duplicates;
      if (r.status == EdgeStatus::kRejected) {
        ++result.rejected;
        result.rejections.push_back("edge " + std::to_string(from) + " -> " + std::to_string(to) +
                                    " rejected: " + r.reason);
      }
      if (schedule.any()) {
        feed_priors(edge.i);
        feed_priors(edge.j);
      }
    }
    fed += static_cast<int>(group.size());
    Stopwatch clock;
    const UpdateStats s = smoother.update();
    const double ms = 1e3 * clock.seconds();
    result.relinearized += s.variables_relinearized;
    result.indeterminate += s.indeterminate_cliques;
    result.rows.push_back({static_cast<int>(result.rows.size()) + 1, fed, ms,
                           s.cliques_reeliminated, s.variables_relinearized, s.cliques_updated,
                           s.cliques_solved});
    result.rows.back().batch_reeliminations = s.batch_reeliminations;
    result.rows.back().cliques_deferred = s.cliques_deferred;
    result.rows.back().async_swapped = s.async_swapped;
    result.rows.back().async_job_running = s.async_pending && !s.async_swapped ? 1 : 0;
    result.rows.back().swap_ms = 1e3 * s.swap_s;
    result.rows.back().prepare_ms = 1e3 * s.prepare_s;
    result.rows.back().top_ms = 1e3 * s.top_s;
    result.rows.back().solve_ms = 1e3 * s.solve_s;
    result.rows.back().reelimination_mflop = 1e-6 * s.reelimination_flops;
    result.rows.back().peak_rss_kb = peakRssKb();
    if (hooks.after_update) hooks.after_update(smoother, result.rows.back());
  }
  // Priors on poses that no edge reaches: each starts a component of its own, in one update.
  if (schedule.any()) {
    bool any = false;
    for (int pose = 0; pose < static_cast<int>(graph.ids.size()); ++pose) {
      if (prior_fed[pose] || schedule.of(pose).empty()) continue;
      prior_fed[pose] = 1;
      any = true;
      for (const PriorRef& p : schedule.of(pose)) feedPrior(graph, p, smoother);
    }
    if (any) smoother.update();
  }
  if (hooks.after_stream) hooks.after_stream(smoother);
  result.F_incremental = result.F_drained = smoother.smoother().objective();
  result.deferred_at_end = smoother.smoother().cliquesDeferred();
  if (result.deferred_at_end > 0) {
    smoother.solveDeferred();
    result.F_drained = smoother.smoother().objective();
  }
  Stopwatch finalize_clock;
  if (settings.finalize) {
    const UpdateStats s = smoother.finalize();
    result.relinearized += s.variables_relinearized;
    result.indeterminate += s.indeterminate_cliques;
    result.finalize_iterations = s.refine_iterations;
  }
  result.finalize_s = finalize_clock.seconds();
  result.pending = smoother.stats().edges_pending;

  std::vector<double> ms;
  for (const auto& r : result.rows) ms.push_back(r.latency_ms);
  result.update_s = std::accumulate(ms.begin(), ms.end(), 0.0) / 1e3;
  if (settings.first_update_edges > 0 && !ms.empty()) {  // the load apart from the stream
    result.first_update_s = ms.front() / 1e3;
    ms.erase(ms.begin());
  }
  result.latency = summarizeLatency(ms);
  result.tenths = summarizeTenths(ms);
  result.total_s = result.update_s + result.finalize_s;

  // The estimate in the graph's dense order (poses never reached keep their graph value).
  result.poses = graph.poses;
  for (const auto& [id, pose] : smoother.estimates()) result.poses[graph.index.at(id)] = pose;
  result.F_final = objective(graph, result.poses);
  result.online = smoother.stats();
  result.closures = smoother.closures();
  if (settings.covariances) {
    result.covariance_ids = smoother.ids();
    result.covariances = smoother.smoother().marginalCovariances();
  }
  return result;
}

template <class G>
std::vector<char> keptEdges(const PoseGraph<G>& graph, const std::vector<ClosureReport>& closures) {
  std::set<std::pair<Key, Key>> rejected;
  for (const ClosureReport& c : closures)
    if (c.status == ClosureStatus::kOutlier) rejected.insert({c.from, c.to});
  std::vector<char> keep(graph.edges.size(), 1);
  for (size_t k = 0; k < graph.edges.size(); ++k)
    if (rejected.count({graph.ids[graph.edges[k].i], graph.ids[graph.edges[k].j]})) keep[k] = 0;
  return keep;
}

template <class G>
ReplayResult<G> runReplay(const PoseGraph<G>& graph, const ReplaySettings& settings) {
  OnlineSmootherOptions<G> options;
  options.smoother = settings.smoother;
  options.robust = settings.robust;
  OnlineSmoother<G> smoother(options);
  ReplayResult<G> result = replayInto(graph, settings, smoother);
  if (settings.batch) {
    result.batch_poses = result.poses;
    if (settings.robust) {  // LM over the edges kept: the false ones would wreck it
      result.batch =
          solveBatch(keepEdges(graph, keptEdges(graph, result.closures)), &result.batch_poses);
    } else {
      result.batch = solveBatch(graph, &result.batch_poses);
    }
  }
  return result;
}

void writeLatencyCsv(const std::string& path, const std::vector<UpdateRow>& rows) {
  std::ofstream csv(path);
  if (!csv) throw std::runtime_error("cannot write " + path);
  csv << "step,edges,latency_ms,cliques_reeliminated,variables_relinearized,cliques_updated,"
         "cliques_solved,async_job_running,async_swapped,swap_ms,prepare_ms,top_ms,solve_ms,"
         "reelimination_mflop,cliques_deferred\n";
  csv << std::setprecision(6);
  for (const auto& r : rows) {
    csv << r.step << "," << r.edges_so_far << "," << r.latency_ms << "," << r.cliques_reeliminated
        << "," << r.variables_relinearized << "," << r.cliques_updated << "," << r.cliques_solved
        << "," << r.async_job_running << "," << r.async_swapped << "," << r.swap_ms << ","
        << r.prepare_ms << "," << r.top_ms << "," << r.solve_ms << "," << r.reelimination_mflop
        << "," << r.cliques_deferred << "\n";
  }
  if (!csv) throw std::runtime_error("error writing " + path);
}

template ReplayResult<SE2> replayInto(const PoseGraph<SE2>&, const ReplaySettings&,
                                      OnlineSmoother<SE2>&, const ReplayHooks<SE2>&);
template ReplayResult<SE3> replayInto(const PoseGraph<SE3>&, const ReplaySettings&,
                                      OnlineSmoother<SE3>&, const ReplayHooks<SE3>&);
template std::vector<char> keptEdges(const PoseGraph<SE2>&, const std::vector<ClosureReport>&);
template std::vector<char> keptEdges(const PoseGraph<SE3>&, const std::vector<ClosureReport>&);
template ReplayResult<SE2> runReplay(const PoseGraph<SE2>&, const ReplaySettings&);
template ReplayResult<SE3> runReplay(const PoseGraph<SE3>&, const ReplaySettings&);

}  // namespace arbor::cli
