#include "arbor/tools/cli/online_threshold.h"

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
  out.noise_scale = st.noise_scale;
  out.estimated = st.noise_scale_estimated;
  out.samples = st.noise_samples;
  out.kept = keptEdges(graph, replay.closures);
  out.replay_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return out;
}

template OnlineThreshold onlineThreshold(const PoseGraph<SE2>&, KernelKind, const EdgeChoices&,
                                         std::vector<SE2>*);
template OnlineThreshold onlineThreshold(const PoseGraph<SE3>&, KernelKind, const EdgeChoices&,
                                         std::vector<SE3>*);

}  // namespace arbor::cli
