#include "arbor_slam/tools/cli/online_threshold.h"

#include <algorithm>
#include <chrono>
#include <utility>

#include "arbor_slam/tools/cli/replay_runner.h"

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
  const refine::OnlineClassification bounds = refine::onlineBounds(
      st.closure_threshold, st.closure_threshold_at_end, robust_constants::kRecheckMargin);
  out.c2 = bounds.c2;
  out.c2_take_back = bounds.c2_take_back;
  out.noise_scale = st.noise_scale;
  out.estimated = st.noise_scale_estimated;
  out.samples = st.noise_samples;
  out.kept = keptEdges(graph, replay.closures);
  out.replay_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return out;
}

template <class G>
OnlineBatch solveGncFromReplay(const PoseGraph<G>& graph, GncOptions options,
                               const EdgeChoices& choices, bool online_threshold,
                               std::vector<G>* poses) {
  OnlineBatch out;
  out.online = onlineThreshold(graph, options.kernel, choices, poses);
  refine::OnlineClassification from;
  from.held_out.resize(out.online.kept.size());
  for (size_t k = 0; k < from.held_out.size(); ++k) from.held_out[k] = !out.online.kept[k];
  if (online_threshold) {
    from.c2 = out.online.c2;
    from.c2_take_back = out.online.c2_take_back;
  }
  static_cast<refine::GncFromOnline&>(out) =
      refine::solveGncFromOnline(graph, std::move(options), from, poses);
  return out;
}

template OnlineThreshold onlineThreshold(const PoseGraph<SE2>&, KernelKind, const EdgeChoices&,
                                         std::vector<SE2>*);
template OnlineThreshold onlineThreshold(const PoseGraph<SE3>&, KernelKind, const EdgeChoices&,
                                         std::vector<SE3>*);
template OnlineBatch solveGncFromReplay(const PoseGraph<SE2>&, GncOptions, const EdgeChoices&, bool,
                                        std::vector<SE2>*);
template OnlineBatch solveGncFromReplay(const PoseGraph<SE3>&, GncOptions, const EdgeChoices&, bool,
                                        std::vector<SE3>*);

}  // namespace arbor::cli
