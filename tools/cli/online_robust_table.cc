#include "arbor/tools/cli/online_robust_table.h"

namespace arbor::cli {

const char* const kRobustSection = "Robust";

namespace {

using R = RobustOptions;

// The numbers are checked by RobustOptions::problem() once all are read.
constexpr Condition kAny{"a number", [](double) { return true; }};

// "--entry must be ...": the enums' parse functions throw the rest of the sentence.
template <class Enum>
auto parseWith(Enum (*parse)(const std::string&)) {
  return [parse](const std::string& text) { return parse(text); };
}

OptionTable<R> makeOnlineTable() {
  constexpr Tier kAdvanced = Tier::kAdvanced, kExperimental = Tier::kExperimental;
  const char* const s = kRobustSection;
  const std::string robust = "robust";
  return {
      wordOption<R>(
          "entry", kAdvanced, s, "innovation|residual",
          "with --robust, how a new loop closure is first judged: innovation (r'(I + A S A')^-1 "
          "r, S the poses' covariance in the Bayes tree) or residual (r'r)",
          [](auto& o) -> auto& { return o.entry; }, parseWith(parseEntryTest),
          [](EntryTest e) { return toString(e); }, robust),
      wordOption<R>(
          "noise-scale", kAdvanced, s, "estimated|given",
          "with --robust, the scale of the information matrices the threshold is put on: "
          "estimated (from the loop closures' innovations) or given (as the file or sender says)",
          [](auto& o) -> auto& { return o.scale; }, parseWith(parseNoiseScale),
          [](NoiseScale e) { return toString(e); }, robust),
      wordOption<R>(
          "warm-up", kExperimental, s, "hold|given",
          "with --robust and --noise-scale estimated, the loop closures that arrive before the "
          "scale is estimated: hold (at weight 0, judged once it is) or given (judged at once, Ω "
          "at its word)",
          [](auto& o) -> auto& { return o.warm_up; }, parseWith(parseWarmUp),
          [](WarmUp e) { return toString(e); }, robust),
      wordOption<R>(
          "scale-start", kExperimental, s, "at-most-last|median",
          "with --robust and --noise-scale estimated, where each re-estimate of the noise scale "
          "starts: at-most-last (the corroborated innovations' median, or the last scale where "
          "that is lower) or median (their median every time; docs/design.md, \"The noise "
          "scale\")",
          [](auto& o) -> auto& { return o.scale_start; }, parseWith(parseScaleStart),
          [](ScaleStart e) { return toString(e); }, robust),
      numberOption<R>(
          "corroboration-window", kExperimental, s, "K",
          "with --robust and --noise-scale estimated, K > 0: the scale is estimated from the "
          "loop closures that another closure within K poses of both ends agrees with "
          "(docs/design.md, \"The noise scale\"); 0: from every closure",
          [](auto& o) -> auto& { return o.corroboration_window; }, kAny, robust),
      numberOption<R>(
          "final-confirm-margin", kExperimental, s, "X",
          "with --robust, the final pass drops an inlier no other inlier agrees with when "
          "keeping it costs the objective more than this many times the threshold (its "
          "leave-one-out innovation; docs/design.md, \"Confirmed at the end\"); 0: off",
          [](auto& o) -> auto& { return o.final_confirm_margin; }, kAny, robust),
      numberOption<R>(
          "end-confirm-margin", kExperimental, s, "X",
          "with --robust, the same margin over the end's own threshold where that is the one in "
          "use (docs/design.md, \"The end's scale\"); > 0",
          [](auto& o) -> auto& { return o.end_confirm_margin; }, kAny, robust),
      numberOption<R>(
          "end-rejected-partners", kExperimental, s, "N",
          "with --robust, the final pass drops an inlier no other inlier agrees with past the "
          "threshold itself, not the margin over it, when at least this many closures agreed "
          "with it on arrival and every one of them has been rejected since (docs/design.md, "
          "\"Disowned at the end\"); 0: off",
          [](auto& o) -> auto& { return o.end_rejected_partners; }, kAny, robust),
      numberOption<R>(
          "finalize-rounds", kExperimental, s, "N",
          "with --robust, at most this many rounds of the final pass (each graduates every "
          "closure to the end and re-checks every closure; another round only while a re-check "
          "changed a weight; every round after the first relinearises everything before its "
          "re-check, and the last one ends relinearised)",
          [](auto& o) -> auto& { return o.finalize_rounds; }, kAny, robust),
      wordOption<R>(
          "first-recheck", kExperimental, s, "replay|relinearized",
          "with --robust, where the final pass's first re-check reads the closures: replay (the "
          "replay's own estimate) or relinearized (after relinearising everything, as the later "
          "rounds do; docs/design.md, \"The first re-check\")",
          [](auto& o) -> auto& { return o.first_recheck; }, parseWith(parseFirstRecheck),
          [](FirstRecheck e) { return toString(e); }, robust),
      numberOption<R>(
          "rehold-growth", kExperimental, s, "X",
          "with --robust, X > 1: when the noise scale is first estimated and that raises the "
          "threshold X times or more, the loop closures rejected before it are judged again as "
          "the warm-up's are (docs/design.md, \"The warm-up\"); 0: off",
          [](auto& o) -> auto& { return o.rehold_growth; }, kAny, robust),
      numberOption<R>(
          "end-scale-samples", kExperimental, s, "N",
          "with --robust, the final pass re-estimates the threshold from the leave-one-out "
          "innovations of at most this many inliers and as many trusted edges, and uses it where "
          "it is tighter (docs/design.md, \"The end's scale\"); 0: off",
          [](auto& o) -> auto& { return o.end_scale_samples; }, kAny, robust),
      numberOption<R>(
          "end-scale-growth", kExperimental, s, "X",
          "with --robust, X > 1: the end's threshold is read during the replay too, each time "
          "the poses have grown X times and the updates' work with them, and where it is tighter "
          "the inliers past it are dropped then (docs/design.md, \"The end's scale on the "
          "way\"); 0: only at the end",
          [](auto& o) -> auto& { return o.end_scale_growth; }, kAny, robust),
      numberOption<R>(
          "end-backed-margin", kExperimental, s, "X",
          "with --robust, the final pass keeps, or takes back, a loop closure within this many "
          "times the threshold when enough inliers agree with it at the end (docs/design.md, "
          "\"Backed at the end\"); 0: off",
          [](auto& o) -> auto& { return o.end_backed_margin; }, kAny, robust),
      numberOption<R>(
          "left-out-backing-margin", kExperimental, s, "X",
          "with --robust, the final pass leaves out each loop closure past its threshold that "
          "other inliers back, and keeps it out unless one still agrees with it, within X times "
          "the pair threshold, at the estimate without it (docs/design.md, \"Backing left "
          "out\"); 0: off",
          [](auto& o) -> auto& { return o.left_out_backing_margin; }, kAny, robust),
  };
}

}  // namespace

const OptionTable<RobustOptions>& onlineRobustOptionTable() {
  static const OptionTable<RobustOptions> table = [] {
    OptionTable<R> rows = makeOnlineTable();
    for (OptionSpec<R>& row : rows) row = inPython(row);  // arbor.RobustOptions' keywords
    return rows;
  }();
  return table;
}

}  // namespace arbor::cli
