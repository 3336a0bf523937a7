#include "arbor_slam/tools/cli/smoother_table.h"

#include <cmath>

namespace arbor::cli {

namespace {

using S = SmootherOptions;

// The section of --help every smoother flag is listed under.
const char* const kSection = "Smoother";

constexpr Condition kNonNegative{">= 0", [](double x) { return x >= 0; }};
constexpr Condition kPositive{"> 0", [](double x) { return x > 0; }};
constexpr Condition kAtLeastOne{">= 1", [](double x) { return x >= 1; }};
constexpr Condition kFiniteNonNegative{"finite and >= 0",
                                       [](double x) { return x >= 0 && std::isfinite(x); }};

// --relinearize-threshold: both β at once (no value of its own; the two specific flags, after
// it in the table, win over it).
OptionSpec<S> bothThresholds(const S& d) {
  OptionSpec<S> spec = numberOption<S>(
      "relinearize-threshold", Tier::kCommon, kSection, "B",
      "β for translation and rotation (default " +
          option_detail::text(d.relinearize_threshold_translation) +
          "; --relinearize-threshold-translation and -rotation win over it)",
      [](auto& o) -> auto& { return o.relinearize_threshold_translation; }, kNonNegative);
  const auto set_translation = spec.set;
  spec.get = [](const S&) -> std::optional<std::string> { return std::nullopt; };
  spec.set = [set_translation](S& o, const std::string& text) {
    set_translation(o, text);
    o.relinearize_threshold_rotation = o.relinearize_threshold_translation;
  };
  return spec;
}

OptionTable<S> makeTable() {
  const S d;
  constexpr Tier kCommon = Tier::kCommon, kAdvanced = Tier::kAdvanced,
                 kExperimental = Tier::kExperimental;
  return {
      bothThresholds(d),
      inPython(numberOption<S>(
          "relinearize-threshold-translation", kAdvanced, kSection, "B",
          "β on the translational part of a variable's step",
          [](auto& o) -> auto& { return o.relinearize_threshold_translation; }, kNonNegative)),
      inPython(numberOption<S>(
          "relinearize-threshold-rotation", kAdvanced, kSection, "B",
          "β on the rotational part of a variable's step",
          [](auto& o) -> auto& { return o.relinearize_threshold_rotation; }, kNonNegative)),
      inPython(numberOption<S>(
          "relinearize-skip", kAdvanced, kSection, "K", "check relinearisation every K updates",
          [](auto& o) -> auto& { return o.relinearize_skip; }, kAtLeastOne)),
      inPython(numberOption<S>(
                   "wildfire", kAdvanced, kSection, "A", "partial back-substitution threshold",
                   [](auto& o) -> auto& { return o.wildfire_threshold; }, kNonNegative),
               "wildfire_threshold"),
      switchOption<S>(
          "full-backsubstitution", kAdvanced, kSection, "solve every clique on each update",
          [](auto& o) -> auto& { return o.full_backsubstitution; }, true),
      inPython(numberOption<S>(
          "solve-budget-mb", kAdvanced, kSection, "X",
          "bounded back-substitution: MB of conditionals an update reads past what it "
          "re-eliminated (0: no bound; the rest is deferred to later updates)",
          [](auto& o) -> auto& { return o.solve_budget_mb; }, kFiniteNonNegative)),
      switchOption<S>(
          "no-rank-updates", kExperimental, kSection,
          "re-eliminate the path of every loop closure (as GTSAM's iSAM2) instead of folding it "
          "in by rank updates",
          [](auto& o) -> auto& { return o.rank_updates; }, false),
      switchOption<S>(
          "no-newest-last", kExperimental, kSection,
          "order only the touched variables last in a re-eliminated top (iSAM2's constraint), "
          "not the newest pose with them",
          [](auto& o) -> auto& { return o.newest_last; }, false),
      inPython(switchOption<S>(
          "dogleg", kCommon, kSection, "Powell's dogleg instead of Gauss-Newton",
          [](auto& o) -> auto& { return o.dogleg; }, true)),
      numberOption<S>(
          "dogleg-radius", kAdvanced, kSection, "R", "dogleg: initial trust-region radius",
          [](auto& o) -> auto& { return o.dogleg_initial_radius; }, kPositive),
      numberOption<S>(
          "dogleg-min-radius", kAdvanced, kSection, "R",
          "dogleg: give up shrinking the radius below this",
          [](auto& o) -> auto& { return o.dogleg_min_radius; }, kPositive),
      numberOption<S>(
          "finalize-rel-tol", kAdvanced, kSection, "X",
          "final relinearise-all pass: stop when F's relative decrease is below this",
          [](auto& o) -> auto& { return o.finalize_relative_tolerance; }, kNonNegative),
      numberOption<S>(
          "finalize-max-iterations", kAdvanced, kSection, "N",
          "final relinearise-all pass: at most this many iterations",
          [](auto& o) -> auto& { return o.finalize_max_iterations; }, kAtLeastOne),
      numberOption<S>("nested-dissection-min", kExperimental, kSection, "N",
                      "order re-eliminated tops of at least N variables by nested dissection (-1: "
                      "automatic, 0: always)",
                      [](auto& o) -> auto& { return o.nested_dissection_min; },
                      {">= -1", [](double x) { return x >= -1; }}),
      inPython(numberOption<S>(
          "threads", kCommon, kSection, "N",
          "threads per update, sharing independent subtrees (0: one per core, at most 4)",
          [](auto& o) -> auto& { return o.threads; }, kNonNegative)),
      numberOption<S>(
          "batch-top-share", kExperimental, kSection, "S",
          "re-eliminate the whole graph in a fresh ordering when the top of an update holds "
          "more than this share of the variables (1: never)",
          [](auto& o) -> auto& { return o.batch.top_share; },
          {"in (0, 1]", [](double x) { return x > 0 && x <= 1; }}),
      numberOption<S>(
          "reorder-decay", kExperimental, kSection, "X",
          "re-order the tree when factorising it in its incremental ordering costs more than "
          "this many times a fresh ordering (0: never)",
          [](auto& o) -> auto& { return o.batch.reorder_decay; },
          {"0 or >= 1", [](double x) { return x == 0 || x >= 1; }}),
      wordOption<S>(
          "relinearize", kAdvanced, kSection, "inline|async",
          "inline: relinearise in the update (exact iSAM2); async: a check marking many "
          "variables relinearises the whole graph on a background thread and swaps it in at a "
          "later update",
          [](auto& o) -> auto& { return o.relinearize; },
          eitherOf("inline", RelinearizationMode::kInline, "async", RelinearizationMode::kAsync),
          [](RelinearizationMode m) {
            return m == RelinearizationMode::kAsync ? "async" : "inline";
          }),
      numberOption<S>(
          "async-min-variables", kAdvanced, kSection, "N",
          "with --relinearize async: a check marking fewer variables relinearises inline",
          [](auto& o) -> auto& { return o.async.min_variables; }, kAtLeastOne),
      wordOption<S>(
          "async-catch-up", kExperimental, kSection, "background|swap",
          "with --relinearize async, where what arrived during the job is folded into its tree: "
          "background (a second job, then the swap folds in only what came meanwhile) or swap "
          "(the swap's update)",
          [](auto& o) -> auto& { return o.async.catch_up; },
          eitherOf("background", AsyncCatchUp::kInBackground, "swap", AsyncCatchUp::kOnSwap),
          [](AsyncCatchUp c) { return c == AsyncCatchUp::kOnSwap ? "swap" : "background"; }),
      wordOption<S>(
          "async-reorder", kExperimental, kSection, "background|inline",
          "with --relinearize async, where a decayed ordering (--reorder-decay) is re-ordered: "
          "background (a job at the next update, as a relinearisation) or inline (a batch "
          "update)",
          [](auto& o) -> auto& { return o.async.reorder_in_background; },
          eitherOf("background", true, "inline", false),
          [](bool background) { return background ? "background" : "inline"; }),
      numberOption<S>(
          "async-reorder-decay", kExperimental, kSection, "X",
          "with --relinearize async and --async-reorder background: ask for a re-ordering job "
          "at this decay (>= 1; at most --reorder-decay, which stays the bound for re-ordering "
          "inline)",
          [](auto& o) -> auto& { return o.async.reorder_decay; }, kAtLeastOne),
      numberOption<S>(
          "async-job-iterations", kExperimental, kSection, "N",
          "with --relinearize async: Gauss-Newton iterations of each background job on its "
          "snapshot (1: one elimination at the relinearised point; more: fewer, longer jobs)",
          [](auto& o) -> auto& { return o.async.job_iterations; }, kAtLeastOne),
      numberOption<S>(
          "async-catch-up-max-factors", kExperimental, kSection, "M",
          "with --relinearize async and --async-catch-up background: a catch-up whose swap "
          "would fold in more than this many factors hands its tree to another catch-up (at "
          "most 3 a job; 0: never)",
          [](auto& o) -> auto& { return o.async.catch_up_max_factors; }, kNonNegative),
      numberOption<S>(
          "cached-factor-max-ratio", kExperimental, kSection, "X",
          "a clique keeps its cached factor (the Schur complement on its separator) only when "
          "it is at most this many times its conditional, S^2 <= X*F(F+S); one without is "
          "re-eliminated with its parent (less memory, more work; 0: every clique keeps it, as "
          "iSAM2)",
          [](auto& o) -> auto& { return o.cached_factors.max_ratio; }, kFiniteNonNegative),
  };
}

}  // namespace

const OptionTable<SmootherOptions>& smootherOptionTable() {
  static const OptionTable<SmootherOptions> table = makeTable();
  return table;
}

}  // namespace arbor::cli
