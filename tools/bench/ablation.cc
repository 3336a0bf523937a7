#include "arbor_slam/tools/bench/ablation.h"

#include <stdexcept>

namespace arbor::bench {

namespace {

// A rule of RobustRule, switched off through RobustOptions::rules_off.
Ablation ruleOff(RobustRule rule, const std::string& guarantees) {
  return {toString(rule), std::string("rules_off = ") + toString(rule), guarantees,
          [rule](RobustOptions* o) { o->rules_off.add(rule); }};
}

}  // namespace

const std::vector<Ablation>& ablations() {
  static const std::vector<Ablation> kRules = {
      ruleOff(RobustRule::kEndWord,
              "no closure ends rejected whose residual at the final estimate is within Ω's χ² "
              "bound"),
      ruleOff(RobustRule::kFinalConfirm,
              "an unbacked inlier whose leave-one-out innovation is past the margin ends "
              "rejected"),
      ruleOff(RobustRule::kEndScale,
              "the end judges by the scale of the whole graph's leave-one-out innovations where "
              "tighter (and reads it on the way)"),
      ruleOff(RobustRule::kRehold,
              "closures rejected at Ω's word are judged again when a late scale raises c² many "
              "times"),
      {"corroboration", "corroboration_window = 0",
       "the scale is estimated from closures another closure agrees with",
       [](RobustOptions* o) { o->corroboration_window = 0; }},
      ruleOff(RobustRule::kScaleStart, "a re-estimate of the scale starts at most at the last one"),
      ruleOff(RobustRule::kWarmUp,
              "closures that arrive before the scale is estimated are held until it is"),
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
