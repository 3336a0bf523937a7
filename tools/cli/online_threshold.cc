#include "arbor/tools/cli/online_threshold.h"

#include <algorithm>
#include <chrono>
#include <utility>

#include "arbor/tools/cli/replay_runner.h"

namespace arbor::cli {

template <class G>
OnlineThreshold onlineThreshold(const PoseGraph<G>& graph, KernelKind kernel,
                                const EdgeChoices& choices, std::vector<G>* estimate) {
  const auto t0 = std::chrono::steady_clock::now();
  ReplaySettings settings;
  settings.finalize = true;  // held closures judged, as `arbor replay --robust` ends
  settings.batch = false;
  RobustOptions robust;
  robust.kernel = kernel;
  settings.robust = robust;
  settings.choices = choices;
  OnlineSmootherOptions<G> options;
  options.smoother = settings.smoother;
  options.robust = robust;
  OnlineSmoother<G> smoother(options);
  ReplayResult<G> replay = replayInto(graph, settings, smoother);
  if (estimate) *estimate = std::move(replay.poses);
  const OnlineStats st = smoother.stats();
  OnlineThreshold out;
  out.c2_in_use = st.closure_threshold;
  out.c2 = robust.recheck_margin * st.closure_threshold;
  out.c2_take_back = st.closure_threshold_at_end > 0
                         ? std::min(st.closure_threshold, st.closure_threshold_at_end)
                         : st.closure_threshold;
  out.noise_scale = st.noise_scale;
  out.estimated = st.noise_scale_estimated;
  out.samples = st.noise_samples;
  out.kept = keptEdges(graph, replay.closures);
  out.replay_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return out;
}

template <class G>
OnlineBatch solveGncFromOnline(const PoseGraph<G>& graph, GncOptions options,
                               const EdgeChoices& choices, bool online_threshold,
                               std::vector<G>* poses) {
  OnlineBatch out;
  out.online = onlineThreshold(graph, options.kernel, choices, poses);
  if (online_threshold) options.threshold = out.online.c2;
  options.known_outliers.assign(graph.numEdges(), 0);
  // The closures the replay's end kept beyond that bound (backed at the end) are its own
  // judgement, not GNC's to undo: held at weight 1 as trusted edges.
  std::vector<char> backed(graph.numEdges(), 0);
  for (int k = 0; k < graph.numEdges(); ++k) {
    const bool trusted = trustedEdge(graph, options, k);
    options.known_outliers[k] = !out.online.kept[k] && !trusted;
    out.known_outliers += options.known_outliers[k];
    const auto& e = graph.edges[static_cast<size_t>(k)];
    backed[k] = online_threshold && out.online.kept[k] && !trusted &&
                e.cost((*poses)[static_cast<size_t>(e.i)], (*poses)[static_cast<size_t>(e.j)]) >
                    out.online.c2;
    out.kept_beyond += backed[k];
  }
  if (out.kept_beyond > 0) {
    if (options.trusted.empty()) options.trusted.assign(graph.numEdges(), 0);
    for (int k = 0; k < graph.numEdges(); ++k) options.trusted[k] |= backed[k];
  }
  out.gnc = solveGnc(graph, poses, options);
  if (!out.gnc.cancelled) {
    const double entry = online_threshold ? out.online.c2_take_back : out.gnc.threshold;
    out.readmitted = readmitFitting(graph, &out.gnc, poses, entry, options.outer);
  }
  return out;
}

template OnlineThreshold onlineThreshold(const PoseGraph<SE2>&, KernelKind, const EdgeChoices&,
                                         std::vector<SE2>*);
template OnlineThreshold onlineThreshold(const PoseGraph<SE3>&, KernelKind, const EdgeChoices&,
                                         std::vector<SE3>*);
template OnlineBatch solveGncFromOnline(const PoseGraph<SE2>&, GncOptions, const EdgeChoices&, bool,
                                        std::vector<SE2>*);
template OnlineBatch solveGncFromOnline(const PoseGraph<SE3>&, GncOptions, const EdgeChoices&, bool,
                                        std::vector<SE3>*);

}  // namespace arbor::cli
