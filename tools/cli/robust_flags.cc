#include "arbor/tools/cli/robust_flags.h"

#include <algorithm>
#include <cmath>
#include <functional>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "arbor/tools/cli/cli_common.h"
#include "arbor/tools/cli/flag_set.h"

namespace arbor::cli {

namespace po = boost::program_options;

const char* const kRobustSection = "Robust";

const char* const kKernelHelp = "with --robust: tls | gm (graduated) | cauchy | huber (reweighted)";
const char* const kInlierThresholdHelp =
    "with --robust: c² on eᵀΩe, a number (2 is GTSAM's barcSq = 1 on ½eᵀΩe, what the shared "
    "robust files need: their Ω are 40-50 times too confident, docs/benchmarks.md); chi2: the "
    "χ² 0.99 quantile of the edge's dimension, Ω taken at its word (GTSAM's default; replay's "
    "and serve's, which scale it by the noise they estimate); online (batch only, its default): "
    "the bound up to which the robust online smoother keeps an inlier after replaying the graph, "
    "twice its threshold, the χ² quantile on the noise scale estimated from its loop closures' "
    "innovations (arbor replay --robust's); auto (batch only, experimental: it "
    "feeds on its own truncation): that quantile times the variance factor estimated over the "
    "inliers";

namespace {

// The four flags, declared once: `at(tier, needs)` gives the add_options() they go into.
void declareRobustFlags(
    const std::function<po::options_description_easy_init(Tier, const char*)>& at,
    const std::string& robust_help, const std::string& default_threshold) {
  at(Tier::kCommon, "")("robust", po::bool_switch(), robust_help.c_str());
  at(Tier::kCommon, "robust")(
      "kernel", po::value<std::string>()->default_value("tls")->value_name("KERNEL"), kKernelHelp)(
      "inlier-threshold",
      po::value<std::string>()->default_value(default_threshold)->value_name("C2"),
      kInlierThresholdHelp);
  at(Tier::kAdvanced, "robust")("rejected-out", po::value<std::string>()->value_name("FILE"),
                                "with --robust: write the rejected edges, `i j` (file ids) a line");
}

}  // namespace

void addRobustFlags(po::options_description& options, const std::string& robust_help,
                    const std::string& default_threshold) {
  declareRobustFlags([&](Tier, const char*) { return options.add_options(); }, robust_help,
                     default_threshold);
}

void addRobustFlags(FlagSet& flags, const std::string& robust_help,
                    const std::string& default_threshold) {
  declareRobustFlags(
      [&](Tier tier, const char* needs) { return flags.add(tier, kRobustSection, needs); },
      robust_help, default_threshold);
}

namespace {

/// The checks of --kernel and --inlier-threshold, into flags.
void parseKernelAndThreshold(const std::string& kernel, const std::string& threshold,
                             bool allow_auto, RobustFlags* flags) {
  try {
    flags->kernel = parseKernelKind(kernel);
  } catch (const std::invalid_argument& e) {
    throw UsageError(std::string("--kernel: ") + e.what());
  }
  if (flags->kernel == KernelKind::kNone)
    throw UsageError("--kernel must be tls, gm, cauchy or huber with --robust, not none");
  if (threshold == "auto" || threshold == "online") {
    if (!allow_auto)
      throw UsageError("--inlier-threshold " + threshold +
                       " is arbor batch only; give chi2 or a number > 0");
    (threshold == "auto" ? flags->estimate_scale : flags->online_threshold) = true;
  } else if (threshold != "chi2") {
    std::size_t used = 0;
    double value = 0;
    try {
      value = std::stod(threshold, &used);
    } catch (const std::exception&) {
      used = 0;
    }
    if (used != threshold.size() || !(value > 0) || !std::isfinite(value))
      throw UsageError("--inlier-threshold must be " +
                       std::string(allow_auto ? "chi2, online, auto" : "chi2") +
                       " or a number > 0, not '" + threshold + "'");
    flags->threshold = value;
  }
}

// "a", "a or b", "a, b or c" (`last` = "or").
std::string listed(const std::vector<std::string>& items, const std::string& last) {
  std::string out;
  for (size_t k = 0; k < items.size(); ++k)
    out += (k == 0 ? "" : k + 1 == items.size() ? " " + last + " " : ", ") + items[k];
  return out;
}

}  // namespace

RobustFlags readRobustFlags(const po::variables_map& vm, bool allow_auto) {
  RobustFlags flags;
  flags.robust = vm.count("robust") && vm["robust"].as<bool>();
  if (!flags.robust) {
    for (const char* flag : {"kernel", "inlier-threshold", "rejected-out"})
      if (vm.count(flag) && !vm[flag].defaulted())
        throw UsageError(std::string("--") + flag + " needs --robust");
    return flags;
  }
  parseKernelAndThreshold(vm["kernel"].as<std::string>(), vm["inlier-threshold"].as<std::string>(),
                          allow_auto, &flags);
  if (vm.count("rejected-out")) flags.rejected_out = vm["rejected-out"].as<std::string>();
  return flags;
}

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
  static const OptionTable<RobustOptions> table = makeOnlineTable();
  return table;
}

void readOnlineRobustFlags(const po::variables_map& vm, bool robust_on, RobustOptions* robust) {
  if (!robust_on) {
    std::vector<std::string> given;
    for (const OptionSpec<RobustOptions>& spec : onlineRobustOptionTable())
      if (vm.count(spec.name) && !vm[spec.name].defaulted()) given.push_back("--" + spec.name);
    if (!given.empty())
      throw UsageError(listed(given, "and") + (given.size() == 1 ? " needs" : " need") +
                       " --robust");
  }
  readOptions(onlineRobustOptionTable(), vm, robust);
  // The numbers are checked by the options' own rule (RobustOptions::problem), which names the
  // field; each flag here is its field's name with '-' for '_'.
  const std::string problem = robust->problem();
  if (problem.empty()) return;
  const std::string prefix = "RobustOptions::";
  if (problem.rfind(prefix, 0) != 0) throw UsageError(problem);
  std::string flag = problem.substr(prefix.size(), problem.find(' ') - prefix.size());
  std::replace(flag.begin(), flag.end(), '_', '-');
  throw UsageError("--" + flag + problem.substr(problem.find(' ')));
}

void readRobustFlags(const std::string& kernel, const std::string& threshold, GncOptions* gnc) {
  RobustFlags flags;
  parseKernelAndThreshold(kernel, threshold, /*allow_auto=*/true, &flags);
  if (flags.online_threshold)
    throw UsageError("--inlier-threshold online is arbor batch only; give chi2, auto or a number");
  gnc->kernel = flags.kernel;
  gnc->threshold = flags.threshold;
  gnc->estimate_scale = flags.estimate_scale;
}

void requireInlineWithRobust(bool robust_on, const SmootherOptions& smoother) {
  if (robust_on && smoother.relinearize == RelinearizationMode::kAsync)
    throw UsageError(
        "--robust needs --relinearize inline: with async the loop closures are judged against an "
        "estimate that lags the background job (docs/design.md, \"Online robust smoothing\")");
  if (robust_on && smoother.solve_budget_mb > 0)
    throw UsageError(
        "--robust needs an unbounded back-substitution (drop --solve-budget-mb): the loop "
        "closures are judged against the estimate, which a budget leaves partly deferred "
        "(docs/design.md, \"A bounded back-substitution\")");
}

}  // namespace arbor::cli
