#include "arbor/tools/bench/robust_replay_hooks.h"

#include "arbor/tools/cli/replay_runner.h"

namespace arbor::bench {
namespace {

template <class G>
RobustEstimate<G> robustReplay(const PoseGraph<G>& graph, KernelKind kernel) {
  cli::ReplaySettings settings;
  settings.batch = false;
  RobustOptions robust;
  robust.kernel = kernel;
  settings.robust = robust;
  const cli::ReplayResult<G> r = cli::runReplay(graph, settings);
  RobustEstimate<G> out;
  out.poses = r.poses;
  const std::vector<char> kept = cli::keptEdges(graph, r.closures);
  out.rejected.resize(kept.size());
  for (size_t k = 0; k < kept.size(); ++k) out.rejected[k] = kept[k] ? 0 : 1;
  out.total_s = r.total_s;
  out.steps = static_cast<int>(r.rows.size());
  out.latency = r.latency;
  out.note = "σ̂² " + std::to_string(r.online.noise_scale) +
             (r.online.noise_scale_estimated ? "" : " (no estimate)");
  return out;
}

template <class G>
CleanReplayFigures cleanReplay(const PoseGraph<G>& graph) {
  cli::ReplaySettings settings;
  settings.batch = false;
  const cli::ReplayResult<G> r = cli::runReplay(graph, settings);
  CleanReplayFigures out;
  out.total_s = r.total_s;
  out.latency = r.latency;
  return out;
}

}  // namespace

RobustReplayHooks robustReplayHooks(KernelKind kernel) {
  RobustReplayHooks h;
  h.robust2 = [kernel](const PoseGraph2& g) { return robustReplay(g, kernel); };
  h.robust3 = [kernel](const PoseGraph3& g) { return robustReplay(g, kernel); };
  h.clean2 = [](const PoseGraph2& g) { return cleanReplay(g); };
  h.clean3 = [](const PoseGraph3& g) { return cleanReplay(g); };
  return h;
}

}  // namespace arbor::bench
