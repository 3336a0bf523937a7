#include "arbor_slam/tools/bench/ablation.h"

#include <stdexcept>

namespace arbor::bench {
const std::vector<Ablation>& ablations() {
  static const std::vector<Ablation> kRules = {
      {"end-word", "end_word = false",
       "no closure ends rejected whose residual at the final estimate is within Ω's χ² bound",
       [](RobustOptions* o) { o->end_word = false; }},
      {"final-confirm", "final_confirm_margin = 0",
       "an unbacked inlier whose leave-one-out innovation is past the margin ends rejected",
       [](RobustOptions* o) { o->final_confirm_margin = 0; }},
      {"disowned", "end_rejected_partners = 0",
       "an inlier whose every partner was rejected is judged without the margin",
       [](RobustOptions* o) { o->end_rejected_partners = 0; }},
      {"end-scale", "end_scale_samples = 0",
       "the end judges by the scale of the whole graph's leave-one-out innovations where "
       "tighter (and reads it on the way)",
       [](RobustOptions* o) { o->end_scale_samples = 0; }},
      {"end-backed", "end_backed_margin = 0",
       "a closure enough inliers agree with is kept within a wider margin at the end",
       [](RobustOptions* o) { o->end_backed_margin = 0; }},
      {"left-out", "left_out_backing_margin = 0",
       "a backed inlier past the bound stays out when its backing fails without it",
       [](RobustOptions* o) { o->left_out_backing_margin = 0; }},
      {"rehold", "rehold_growth = 0",
       "closures rejected at Ω's word are judged again when a late scale raises c² many times",
       [](RobustOptions* o) { o->rehold_growth = 0; }},
      {"corroboration", "corroboration_window = 0",
       "the scale is estimated from closures another closure agrees with",
       [](RobustOptions* o) { o->corroboration_window = 0; }},
      {"scale-start", "scale_start = median",
       "a re-estimate of the scale starts at most at the last one",
       [](RobustOptions* o) { o->scale_start = ScaleStart::kMedian; }},
      {"warm-up", "warm_up = given",
       "closures that arrive before the scale is estimated are held until it is",
       [](RobustOptions* o) { o->warm_up = WarmUp::kGiven; }},
      {"estimated-scale", "scale = given",
       "the threshold is put on the noise scale estimated from the closures, not on Ω's word",
       [](RobustOptions* o) { o->scale = NoiseScale::kGiven; }},
  };
  return kRules;
}

const Ablation& ablation(const std::string& name) {
  std::string known;
  for (const Ablation& a : ablations()) {
    if (a.name == name) return a;
    known += (known.empty() ? "" : ", ") + a.name;
  }
  throw std::invalid_argument("--ablate: unknown rule '" + name + "' (" + known + ")");
}

RobustOptions ablated(const std::string& name, RobustOptions options) {
  ablation(name).off(&options);
  return options;
}

}  // namespace arbor::bench
