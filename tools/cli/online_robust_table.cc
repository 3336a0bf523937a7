#include "arbor_slam/tools/cli/online_robust_table.h"

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
  constexpr Tier kAdvanced = Tier::kAdvanced;
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
      numberOption<R>(
          "corroboration-window", kAdvanced, s, "K",
          "with --robust and --noise-scale estimated, K > 0: the scale is estimated from the "
          "loop closures that another closure within K poses of both ends agrees with "
          "(docs/design.md, \"Online robust smoothing\"); 0: from every closure",
          [](auto& o) -> auto& { return o.corroboration_window; }, kAny, robust),
      numberOption<R>(
          "finalize-rounds", kAdvanced, s, "N",
          "with --robust, at most this many rounds of the final pass (each graduates every "
          "closure to the end and re-checks every closure; another round only while a re-check "
          "changed a weight)",
          [](auto& o) -> auto& { return o.finalize_rounds; }, kAny, robust),
      wordOption<R>(
          "rules-off", kAdvanced, s, "RULE,...",
          "with --robust, these rules of the robust layer switched off, comma-separated "
          "(warm-up, rehold, scale-start, final-confirm, end-scale, end-word; docs/design.md, "
          "\"Online robust smoothing\"): to see what one does, not to tune a file",
          [](auto& o) -> auto& { return o.rules_off; }, parseWith(parseRuleSet),
          [](const RuleSet& r) { return r.toString(); }, robust),
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
