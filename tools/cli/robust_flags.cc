#include "arbor_slam/tools/cli/robust_flags.h"

#include <algorithm>
#include <cmath>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "arbor_slam/tools/cli/cli_common.h"

namespace arbor::cli {

namespace po = boost::program_options;

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

void addRobustFlags(po::options_description& options, const std::string& robust_help,
                    const std::string& default_threshold) {
  options.add_options()("robust", po::bool_switch(), robust_help.c_str())(
      "kernel", po::value<std::string>()->default_value("tls"), kKernelHelp)(
      "inlier-threshold", po::value<std::string>()->default_value(default_threshold),
      kInlierThresholdHelp)("rejected-out", po::value<std::string>(),
                            "with --robust: write the rejected edges, `i j` (file ids) a line");
}

namespace {

// A default as --help prints it: "1.1", not boost's round-trip "1.1000000000000001".
std::string shortText(double x) {
  std::ostringstream os;
  os << x;
  return os.str();
}

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

// The flags of addOnlineRobustFlags, all of which need --robust.
constexpr const char* kOnlineFlags[] = {"entry",
                                        "noise-scale",
                                        "warm-up",
                                        "scale-start",
                                        "corroboration-window",
                                        "final-confirm-margin",
                                        "end-confirm-margin",
                                        "end-rejected-partners",
                                        "finalize-rounds",
                                        "first-recheck",
                                        "rehold-growth",
                                        "end-scale-samples",
                                        "end-scale-growth",
                                        "end-backed-margin",
                                        "left-out-backing-margin"};

// The value of a flag that names an enum's value (`parse`: the enum's inverse of toString);
// anything else is refused naming the flag, the choices and the value.
template <class Enum>
Enum choiceOf(const po::variables_map& vm, const std::string& flag,
              Enum (*parse)(const std::string&)) {
  try {
    return parse(vm[flag].as<std::string>());
  } catch (const std::invalid_argument& e) {
    throw UsageError("--" + flag + " " + e.what());
  }
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

void addOnlineRobustFlags(po::options_description& options) {
  options.add_options()(
      "entry", po::value<std::string>()->default_value("innovation"),
      "with --robust, how a new loop closure is first judged: innovation (r'(I + A S A')^-1 r, "
      "S the poses' covariance in the Bayes tree) or residual (r'r)")(
      "noise-scale", po::value<std::string>()->default_value("estimated"),
      "with --robust, the scale of the information matrices the threshold is put on: estimated "
      "(from the loop closures' innovations) or given (as the file or sender says)")(
      "warm-up", po::value<std::string>()->default_value("hold"),
      "with --robust and --noise-scale estimated, the loop closures that arrive before the "
      "scale is estimated: hold (at weight 0, judged once it is) or given (judged at once, Ω at "
      "its word)")(
      "scale-start", po::value<std::string>()->default_value("at-most-last"),
      "with --robust and --noise-scale estimated, where each re-estimate of the noise scale "
      "starts: at-most-last (the corroborated innovations' median, or the last scale where that "
      "is lower) or median (their median every time; docs/design.md, \"The noise scale\")")(
      "corroboration-window", po::value<int>()->default_value(RobustOptions{}.corroboration_window),
      "with --robust and --noise-scale estimated, K > 0: the scale is estimated from the loop "
      "closures that another closure within K poses of both ends agrees with (docs/design.md, "
      "\"The noise scale\"); 0: from every closure")(
      "final-confirm-margin",
      po::value<double>()->default_value(RobustOptions{}.final_confirm_margin),
      "with --robust, the final pass drops an inlier no other inlier agrees with when keeping it "
      "costs the objective more than this many times the threshold (its leave-one-out "
      "innovation; docs/design.md, \"Confirmed at the end\"); 0: off")(
      "end-confirm-margin", po::value<double>()->default_value(RobustOptions{}.end_confirm_margin),
      "with --robust, the same margin over the end's own threshold where that is the one in "
      "use (docs/design.md, \"The end's scale\"); > 0")(
      "end-rejected-partners",
      po::value<int>()->default_value(RobustOptions{}.end_rejected_partners),
      "with --robust, the final pass drops an inlier no other inlier agrees with past the "
      "threshold itself, not the margin over it, when at least this many closures agreed with "
      "it on arrival and every one of them has been rejected since (docs/design.md, \"Disowned "
      "at the end\"); 0: off")(
      "finalize-rounds", po::value<int>()->default_value(RobustOptions{}.finalize_rounds),
      "with --robust, at most this many rounds of the final pass (each graduates every closure "
      "to the end and re-checks every closure; another round only while a re-check changed a "
      "weight; every round after the first relinearises everything before its re-check, and "
      "the last one ends relinearised)")(
      "first-recheck", po::value<std::string>()->default_value("replay"),
      "with --robust, where the final pass's first re-check reads the closures: replay (the "
      "replay's own estimate) or relinearized (after relinearising everything, as the later "
      "rounds do; docs/design.md, \"The first re-check\")")(
      "rehold-growth", po::value<double>()->default_value(RobustOptions{}.rehold_growth),
      "with --robust, X > 1: when the noise scale is first estimated and that raises the "
      "threshold X times or more, the loop closures rejected before it are judged again as the "
      "warm-up's are (docs/design.md, \"The warm-up\"); 0: off")(
      "end-scale-samples", po::value<int>()->default_value(RobustOptions{}.end_scale_samples),
      "with --robust, the final pass re-estimates the threshold from the leave-one-out "
      "innovations of at most this many inliers and as many trusted edges, and uses it where it "
      "is tighter (docs/design.md, \"The end's scale\"); 0: off")(
      "end-scale-growth", po::value<double>()->default_value(RobustOptions{}.end_scale_growth),
      "with --robust, X > 1: the end's threshold is read during the replay too, each time the "
      "poses have grown X times and the updates' work with them, and where it is tighter the "
      "inliers past it are dropped then (docs/design.md, \"The end's scale on the way\"); 0: "
      "only at the end")(
      "end-backed-margin", po::value<double>()->default_value(RobustOptions{}.end_backed_margin),
      "with --robust, the final pass keeps, or takes back, a loop closure within this many "
      "times the threshold when enough inliers agree with it at the end (docs/design.md, "
      "\"Backed at the end\"); 0: off")(
      "left-out-backing-margin",
      po::value<double>()->default_value(RobustOptions{}.left_out_backing_margin,
                                         shortText(RobustOptions{}.left_out_backing_margin)),
      "with --robust, the final pass leaves out each loop closure past its threshold that other "
      "inliers back, and keeps it out unless one still agrees with it, within X times the pair "
      "threshold, at the estimate without it (docs/design.md, \"Backing left out\"); 0: off");
}

void readOnlineRobustFlags(const po::variables_map& vm, bool robust_on, RobustOptions* robust) {
  if (!robust_on) {
    std::vector<std::string> given;
    for (const char* flag : kOnlineFlags)
      if (!vm[flag].defaulted()) given.push_back(std::string("--") + flag);
    if (!given.empty())
      throw UsageError(listed(given, "and") + (given.size() == 1 ? " needs" : " need") +
                       " --robust");
  }
  robust->entry = choiceOf(vm, "entry", parseEntryTest);
  robust->scale = choiceOf(vm, "noise-scale", parseNoiseScale);
  robust->warm_up = choiceOf(vm, "warm-up", parseWarmUp);
  robust->first_recheck = choiceOf(vm, "first-recheck", parseFirstRecheck);
  robust->scale_start = choiceOf(vm, "scale-start", parseScaleStart);
  robust->corroboration_window = vm["corroboration-window"].as<int>();
  robust->final_confirm_margin = vm["final-confirm-margin"].as<double>();
  robust->end_confirm_margin = vm["end-confirm-margin"].as<double>();
  robust->end_rejected_partners = vm["end-rejected-partners"].as<int>();
  robust->finalize_rounds = vm["finalize-rounds"].as<int>();
  robust->end_scale_samples = vm["end-scale-samples"].as<int>();
  robust->end_scale_growth = vm["end-scale-growth"].as<double>();
  robust->rehold_growth = vm["rehold-growth"].as<double>();
  robust->end_backed_margin = vm["end-backed-margin"].as<double>();
  robust->left_out_backing_margin = vm["left-out-backing-margin"].as<double>();
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
