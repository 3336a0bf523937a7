// The replay rows of `arbor bench robust` (RobustReplayHooks, robust_bench.h): the robust replay
// exactly as `arbor replay --robust` runs it (one update per edge, the online GNC's defaults:
// innovation entry test, estimated noise scale, warm-up held; the final relinearise-all pass,
// no batch LM), its rejected edges the closures it ends as outliers; and the clean replay of
// the base file (`arbor replay BASE.g2o` without its batch LM), the cost goals' denominator;
// each the fastest of a few runs where the bench asks for more than one (--repeat).
#pragma once

#include "arbor_slam/bayestree/online_gnc.h"
#include "arbor_slam/core/robust_kernel.h"
#include "arbor_slam/tools/bench/robust_bench.h"

namespace arbor::bench {

/// Hooks for both dimensions, the closures graduating towards `kernel`; each replay is run
/// `repeats` times (≥ 1) and the fastest run's figures kept (the runs differ only in time).
/// `online`: the online layer's options but the kernel (default: RobustOptions{}, the
/// defaults of `arbor replay --robust`; an ablation's, tools/bench/ablation.h).
RobustReplayHooks robustReplayHooks(KernelKind kernel, int repeats = 1,
                                    const RobustOptions& online = {});

}  // namespace arbor::bench
