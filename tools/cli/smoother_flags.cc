#include "arbor_slam/tools/cli/smoother_flags.h"

#include <cmath>
#include <sstream>

#include "arbor_slam/tools/cli/cli_common.h"

namespace arbor::cli {

namespace po = boost::program_options;

namespace {

// A value as a user would type it: 0.1, 1e-06, 10.
template <class T>
std::string text(T value) {
  std::ostringstream out;
  out << value;
  return out.str();
}

// The value of `flag` in `vm`, or `fallback` when the description did not have it.
template <class T>
T valueOf(const po::variables_map& vm, const char* flag, T fallback) {
  return vm.count(flag) ? vm[flag].as<T>() : fallback;
}

// Whether `flag` was given on the command line (not only defaulted).
bool given(const po::variables_map& vm, const char* flag) {
  return vm.count(flag) && !vm[flag].defaulted();
}

// Throws UsageError "--FLAG must be CONDITION, not 'VALUE'" unless `ok`.
template <class T>
void require(bool ok, const char* flag, const char* condition, T value) {
  if (!ok) {
    throw UsageError(std::string("--") + flag + " must be " + condition + ", not '" + text(value) +
                     "'");
  }
}

// A flag that takes one of two words: whether it names the second (`current` when not given).
// Throws UsageError "--FLAG must be FIRST or SECOND, not 'VALUE'" on any other word.
bool isSecondChoice(const po::variables_map& vm, const char* flag, const char* first,
                    const char* second, bool current) {
  if (!vm.count(flag)) return current;
  const std::string word = vm[flag].as<std::string>();
  require(word == first || word == second, flag, (std::string(first) + " or " + second).c_str(),
          word);
  return word == second;
}

}  // namespace

void addSmootherFlags(po::options_description& options, const SmootherOptions& d) {
  options.add_options()(
      "relinearize-threshold", po::value<double>(),
      ("β for translation and rotation (default " + text(d.relinearize_threshold_translation) +
       "; the two flags below win over it)")
          .c_str())("relinearize-threshold-translation",
                    po::value<double>()->default_value(d.relinearize_threshold_translation,
                                                       text(d.relinearize_threshold_translation)),
                    "β on the translational part of a variable's step")(
      "relinearize-threshold-rotation",
      po::value<double>()->default_value(d.relinearize_threshold_rotation,
                                         text(d.relinearize_threshold_rotation)),
      "β on the rotational part of a variable's step")(
      "relinearize-skip", po::value<int>()->default_value(d.relinearize_skip),
      "check relinearisation every K updates")(
      "wildfire",
      po::value<double>()->default_value(d.wildfire_threshold, text(d.wildfire_threshold)),
      "partial back-substitution threshold")("full-backsubstitution", po::bool_switch(),
                                             "solve every clique on each update")(
      "solve-budget-mb", po::value<double>()->default_value(d.solve_budget_mb),
      "bounded back-substitution: MB of conditionals an update reads past what it "
      "re-eliminated (0: no bound; the rest is deferred to later updates)")(
      "no-rank-updates", po::bool_switch(),
      "re-eliminate the path of every loop closure (as GTSAM's iSAM2) instead of folding it in "
      "by rank updates")("no-newest-last", po::bool_switch(),
                         "order only the touched variables last in a re-eliminated top (iSAM2's "
                         "constraint), not the newest pose with them")(
      "dogleg", po::bool_switch(), "Powell's dogleg instead of Gauss-Newton")(
      "dogleg-radius",
      po::value<double>()->default_value(d.dogleg_initial_radius, text(d.dogleg_initial_radius)),
      "dogleg: initial trust-region radius")(
      "dogleg-min-radius",
      po::value<double>()->default_value(d.dogleg_min_radius, text(d.dogleg_min_radius)),
      "dogleg: give up shrinking the radius below this")(
      "finalize-rel-tol",
      po::value<double>()->default_value(d.finalize_relative_tolerance,
                                         text(d.finalize_relative_tolerance)),
      "final relinearise-all pass: stop when F's relative decrease is below this")(
      "finalize-max-iterations", po::value<int>()->default_value(d.finalize_max_iterations),
      "final relinearise-all pass: at most this many iterations")(
      "nested-dissection-min", po::value<int>()->default_value(d.nested_dissection_min),
      "order re-eliminated tops of at least N variables by nested dissection (-1: automatic, "
      "0: always)")(
      "threads", po::value<int>()->default_value(d.threads),
      "threads per update, sharing independent subtrees (0: one per core, at most 4)")(
      "batch-top-share",
      po::value<double>()->default_value(d.batch.top_share, text(d.batch.top_share)),
      "re-eliminate the whole graph in a fresh ordering when the top of an update holds more "
      "than this share of the variables (1: never)")(
      "reorder-decay",
      po::value<double>()->default_value(d.batch.reorder_decay, text(d.batch.reorder_decay)),
      "re-order the tree when factorising it in its incremental ordering costs more than this "
      "many times a fresh ordering (0: never)")(
      "relinearize",
      po::value<std::string>()->default_value(
          d.relinearize == RelinearizationMode::kAsync ? "async" : "inline"),
      "inline: relinearise in the update (exact iSAM2); async: a check marking many variables "
      "relinearises the whole graph on a background thread and swaps it in at a later update")(
      "async-min-variables", po::value<int>()->default_value(d.async.min_variables),
      "with --relinearize async: a check marking fewer variables relinearises inline")(
      "async-catch-up",
      po::value<std::string>()->default_value(
          d.async.catch_up == AsyncCatchUp::kInBackground ? "background" : "swap"),
      "with --relinearize async, where what arrived during the job is folded into its tree: "
      "background (a second job, then the swap folds in only what came meanwhile) or swap (the "
      "swap's update)")(
      "async-reorder",
      po::value<std::string>()->default_value(d.async.reorder_in_background ? "background"
                                                                            : "inline"),
      "with --relinearize async, where a decayed ordering (--reorder-decay) is re-ordered: "
      "background (a job at the next update, as a relinearisation) or inline (a batch update)")(
      "async-reorder-decay",
      po::value<double>()->default_value(d.async.reorder_decay, text(d.async.reorder_decay)),
      "with --relinearize async and --async-reorder background: ask for a re-ordering job at "
      "this decay (>= 1; at most --reorder-decay, which stays the bound for re-ordering inline)")(
      "async-job-iterations", po::value<int>()->default_value(d.async.job_iterations),
      "with --relinearize async: Gauss-Newton iterations of each background job on its snapshot "
      "(1: one elimination at the relinearised point; more: fewer, longer jobs)")(
      "async-catch-up-max-factors", po::value<int>()->default_value(d.async.catch_up_max_factors),
      "with --relinearize async and --async-catch-up background: a catch-up whose swap would "
      "fold in more than this many factors hands its tree to another catch-up (at most 3 a job; "
      "0: never)")(
      "cached-factor-max-ratio",
      po::value<double>()->default_value(d.cached_factors.max_ratio,
                                         text(d.cached_factors.max_ratio)),
      "a clique keeps its cached factor (the Schur complement on its separator) only when it is "
      "at most this many times its conditional, S^2 <= X*F(F+S); one without is re-eliminated "
      "with its parent (less memory, more work; 0: every clique keeps it, as iSAM2)");
}

SmootherOptions readSmootherFlags(const po::variables_map& vm, const SmootherOptions& defaults) {
  SmootherOptions o = defaults;
  if (given(vm, "relinearize-threshold")) {
    const double beta = vm["relinearize-threshold"].as<double>();
    require(beta >= 0, "relinearize-threshold", ">= 0", beta);
    o.relinearize_threshold_translation = beta;
    o.relinearize_threshold_rotation = beta;
  }
  if (given(vm, "relinearize-threshold-translation"))
    o.relinearize_threshold_translation = vm["relinearize-threshold-translation"].as<double>();
  if (given(vm, "relinearize-threshold-rotation"))
    o.relinearize_threshold_rotation = vm["relinearize-threshold-rotation"].as<double>();
  require(o.relinearize_threshold_translation >= 0, "relinearize-threshold-translation", ">= 0",
          o.relinearize_threshold_translation);
  require(o.relinearize_threshold_rotation >= 0, "relinearize-threshold-rotation", ">= 0",
          o.relinearize_threshold_rotation);

  o.relinearize_skip = valueOf(vm, "relinearize-skip", o.relinearize_skip);
  require(o.relinearize_skip >= 1, "relinearize-skip", ">= 1", o.relinearize_skip);
  o.wildfire_threshold = valueOf(vm, "wildfire", o.wildfire_threshold);
  require(o.wildfire_threshold >= 0, "wildfire", ">= 0", o.wildfire_threshold);
  o.full_backsubstitution = o.full_backsubstitution || valueOf(vm, "full-backsubstitution", false);
  o.solve_budget_mb = valueOf(vm, "solve-budget-mb", o.solve_budget_mb);
  require(o.solve_budget_mb >= 0 && std::isfinite(o.solve_budget_mb), "solve-budget-mb",
          "finite and >= 0", o.solve_budget_mb);
  o.rank_updates = o.rank_updates && !valueOf(vm, "no-rank-updates", false);
  o.newest_last = o.newest_last && !valueOf(vm, "no-newest-last", false);
  o.dogleg = o.dogleg || valueOf(vm, "dogleg", false);
  o.dogleg_initial_radius = valueOf(vm, "dogleg-radius", o.dogleg_initial_radius);
  require(o.dogleg_initial_radius > 0, "dogleg-radius", "> 0", o.dogleg_initial_radius);
  o.dogleg_min_radius = valueOf(vm, "dogleg-min-radius", o.dogleg_min_radius);
  require(o.dogleg_min_radius > 0, "dogleg-min-radius", "> 0", o.dogleg_min_radius);
  o.finalize_relative_tolerance = valueOf(vm, "finalize-rel-tol", o.finalize_relative_tolerance);
  require(o.finalize_relative_tolerance >= 0, "finalize-rel-tol", ">= 0",
          o.finalize_relative_tolerance);
  o.finalize_max_iterations = valueOf(vm, "finalize-max-iterations", o.finalize_max_iterations);
  require(o.finalize_max_iterations >= 1, "finalize-max-iterations", ">= 1",
          o.finalize_max_iterations);
  o.nested_dissection_min = valueOf(vm, "nested-dissection-min", o.nested_dissection_min);
  require(o.nested_dissection_min >= -1, "nested-dissection-min", ">= -1", o.nested_dissection_min);
  o.threads = valueOf(vm, "threads", o.threads);
  require(o.threads >= 0, "threads", ">= 0", o.threads);
  o.batch.top_share = valueOf(vm, "batch-top-share", o.batch.top_share);
  require(o.batch.top_share > 0 && o.batch.top_share <= 1, "batch-top-share", "in (0, 1]",
          o.batch.top_share);
  o.batch.reorder_decay = valueOf(vm, "reorder-decay", o.batch.reorder_decay);
  require(o.batch.reorder_decay == 0 || o.batch.reorder_decay >= 1, "reorder-decay", "0 or >= 1",
          o.batch.reorder_decay);
  o.relinearize = isSecondChoice(vm, "relinearize", "inline", "async",
                                 o.relinearize == RelinearizationMode::kAsync)
                      ? RelinearizationMode::kAsync
                      : RelinearizationMode::kInline;
  o.async.min_variables = valueOf(vm, "async-min-variables", o.async.min_variables);
  require(o.async.min_variables >= 1, "async-min-variables", ">= 1", o.async.min_variables);
  o.async.catch_up = isSecondChoice(vm, "async-catch-up", "background", "swap",
                                    o.async.catch_up == AsyncCatchUp::kOnSwap)
                         ? AsyncCatchUp::kOnSwap
                         : AsyncCatchUp::kInBackground;
  o.async.reorder_in_background =
      !isSecondChoice(vm, "async-reorder", "background", "inline", !o.async.reorder_in_background);
  o.async.reorder_decay = valueOf(vm, "async-reorder-decay", o.async.reorder_decay);
  require(o.async.reorder_decay >= 1, "async-reorder-decay", ">= 1", o.async.reorder_decay);
  o.async.job_iterations = valueOf(vm, "async-job-iterations", o.async.job_iterations);
  require(o.async.job_iterations >= 1, "async-job-iterations", ">= 1", o.async.job_iterations);
  o.async.catch_up_max_factors =
      valueOf(vm, "async-catch-up-max-factors", o.async.catch_up_max_factors);
  require(o.async.catch_up_max_factors >= 0, "async-catch-up-max-factors", ">= 0",
          o.async.catch_up_max_factors);
  o.cached_factors.max_ratio = valueOf(vm, "cached-factor-max-ratio", o.cached_factors.max_ratio);
  require(o.cached_factors.max_ratio >= 0 && std::isfinite(o.cached_factors.max_ratio),
          "cached-factor-max-ratio", "finite and >= 0", o.cached_factors.max_ratio);
  if (o.relinearize == RelinearizationMode::kAsync && o.dogleg)
    throw UsageError("--relinearize async needs Gauss-Newton: drop --dogleg");
  if (o.solve_budget_mb > 0 && (o.dogleg || o.full_backsubstitution))
    throw UsageError(
        "--solve-budget-mb needs Gauss-Newton and partial back-substitution: drop --dogleg and "
        "--full-backsubstitution");
  return o;
}

std::string describeSmoother(const SmootherOptions& o) {
  const SmootherOptions d;
  std::ostringstream out;
  out << (o.dogleg ? "dogleg" : "GN") << ", β = ";
  if (o.relinearize_threshold_translation == o.relinearize_threshold_rotation) {
    out << o.relinearize_threshold_translation;
  } else {
    out << o.relinearize_threshold_translation << " (translation) / "
        << o.relinearize_threshold_rotation << " (rotation)";
  }
  out << ", skip " << o.relinearize_skip << ", wildfire " << o.wildfire_threshold;
  if (o.dogleg && (o.dogleg_initial_radius != d.dogleg_initial_radius ||
                   o.dogleg_min_radius != d.dogleg_min_radius)) {
    out << ", radius " << o.dogleg_initial_radius << " (min " << o.dogleg_min_radius << ")";
  }
  if (o.full_backsubstitution) out << ", full back-substitution";
  if (o.solve_budget_mb > 0) out << ", solve budget " << o.solve_budget_mb << " MB";
  if (!o.rank_updates) out << ", no rank updates";
  if (!o.newest_last) out << ", no newest-last";
  if (o.nested_dissection_min != d.nested_dissection_min)
    out << ", nested dissection from " << o.nested_dissection_min << " variables";
  if (o.threads != d.threads) out << ", " << o.threads << " thread(s)";
  if (o.batch.top_share != d.batch.top_share)
    out << ", batch past a top share of " << o.batch.top_share;
  if (o.batch.reorder_decay != d.batch.reorder_decay)
    out << ", re-order at decay " << o.batch.reorder_decay;
  if (o.cached_factors.max_ratio != d.cached_factors.max_ratio)
    out << ", cached factors up to " << o.cached_factors.max_ratio << "x the conditional";
  if (o.relinearize == RelinearizationMode::kAsync) {
    out << ", async relinearisation";
    if (o.async.min_variables != d.async.min_variables)
      out << " from " << o.async.min_variables << " variables";
    if (o.async.catch_up != d.async.catch_up) out << ", catch-up on the swap";
    if (o.async.reorder_in_background != d.async.reorder_in_background)
      out << ", re-ordering inline";
    else if (o.async.reorder_decay != d.async.reorder_decay)
      out << ", re-ordering job at decay " << o.async.reorder_decay;
    if (o.async.job_iterations != d.async.job_iterations)
      out << ", " << o.async.job_iterations << " Gauss-Newton iterations a job";
  }
  if (o.finalize_relative_tolerance != d.finalize_relative_tolerance ||
      o.finalize_max_iterations != d.finalize_max_iterations) {
    out << ", final pass to " << o.finalize_relative_tolerance << " in at most "
        << o.finalize_max_iterations << " iterations";
  }
  return out.str();
}

}  // namespace arbor::cli
