#include "arbor_slam/tools/cli/robust_flags.h"

#include <algorithm>
#include <cmath>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "arbor_slam/tools/cli/cli_common.h"
#include "arbor_slam/tools/cli/flag_set.h"

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

void addRobustFlags(FlagSet& flags, const std::string& robust_help,
                    const std::string& default_threshold) {
  flags.add(Tier::kCommon, kRobustSection)("robust", po::bool_switch(), robust_help.c_str());
  flags.add(Tier::kCommon, kRobustSection, "robust")(
      "kernel", po::value<std::string>()->default_value("tls")->value_name("KERNEL"), kKernelHelp)(
      "inlier-threshold",
      po::value<std::string>()->default_value(default_threshold)->value_name("C2"),
      kInlierThresholdHelp);
  flags.add(Tier::kAdvanced, kRobustSection, "robust")(
      "rejected-out", po::value<std::string>()->value_name("FILE"),
      "with --robust: write the rejected edges, `i j` (file ids) a line");
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
