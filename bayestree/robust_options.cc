#include "arbor_slam/bayestree/robust_options.h"

#include <cmath>
#include <initializer_list>
#include <sstream>
#include <stdexcept>

namespace arbor {

const char* toString(EntryTest entry) {
  return entry == EntryTest::kInnovation ? "innovation" : "residual";
}
const char* toString(NoiseScale scale) {
  return scale == NoiseScale::kEstimated ? "estimated" : "given";
}
const char* toString(RobustRule rule) {
  switch (rule) {
    case RobustRule::kWarmUp:
      return "warm-up";
    case RobustRule::kRehold:
      return "rehold";
    case RobustRule::kScaleStart:
      return "scale-start";
    case RobustRule::kFinalConfirm:
      return "final-confirm";
    case RobustRule::kEndScale:
      return "end-scale";
    case RobustRule::kEndWord:
      return "end-word";
  }
  return "?";
}

const std::vector<RobustRule>& robustRules() {
  static const std::vector<RobustRule> kRules = {RobustRule::kWarmUp,     RobustRule::kRehold,
                                                 RobustRule::kScaleStart, RobustRule::kFinalConfirm,
                                                 RobustRule::kEndScale,   RobustRule::kEndWord};
  return kRules;
}

RuleSet::RuleSet(std::initializer_list<RobustRule> rules) {
  for (RobustRule r : rules) add(r);
}

RuleSet& RuleSet::add(RobustRule rule) {
  bits_ |= bit(rule);
  return *this;
}

std::string RuleSet::toString() const {
  std::string names;
  for (RobustRule r : robustRules())
    if (has(r)) names += (names.empty() ? "" : ",") + std::string(arbor::toString(r));
  return names;
}

namespace {

// The choice whose toString() is `text`.
template <class Enum>
Enum parseChoice(const std::string& text, const std::vector<Enum>& choices) {
  std::string names;
  size_t k = 0;
  for (const Enum choice : choices) {
    if (text == toString(choice)) return choice;
    names += std::string(k == 0 ? "" : k + 1 == choices.size() ? " or " : ", ") + toString(choice);
    ++k;
  }
  throw std::invalid_argument("must be " + names + ", not '" + text + "'");
}

}  // namespace

EntryTest parseEntryTest(const std::string& text) {
  return parseChoice(text, std::vector<EntryTest>{EntryTest::kInnovation, EntryTest::kResidual});
}
NoiseScale parseNoiseScale(const std::string& text) {
  return parseChoice(text, std::vector<NoiseScale>{NoiseScale::kEstimated, NoiseScale::kGiven});
}
RobustRule parseRobustRule(const std::string& text) { return parseChoice(text, robustRules()); }

RuleSet parseRuleSet(const std::string& text) {
  RuleSet set;
  if (text.empty() || text == "none") return set;
  std::istringstream in(text);
  std::string name;
  while (std::getline(in, name, ',')) set.add(parseRobustRule(name));
  return set;
}

std::string RobustOptions::problem() const {
  auto bad = [](const std::string& field, double value, const std::string& want) {
    std::ostringstream out;
    out << "RobustOptions::" << field << " must be " << want << ", not " << value;
    return out.str();
  };
  if (kernel == KernelKind::kNone)
    return "RobustOptions::kernel must be tls, gm, cauchy or huber, not none";
  if (!std::isfinite(threshold)) return bad("threshold", threshold, "finite (≤ 0: automatic)");
  if (!(confidence > 0 && confidence < 1)) return bad("confidence", confidence, "in (0, 1)");
  if (!(mu_step > 1) || !std::isfinite(mu_step)) return bad("mu_step", mu_step, "finite and > 1");
  if (steps_per_update < 1) return bad("steps_per_update", steps_per_update, ">= 1");
  if (max_steps_per_closure < 1) return bad("max_steps_per_closure", max_steps_per_closure, ">= 1");
  if (rechecks_per_update < 0) return bad("rechecks_per_update", rechecks_per_update, ">= 0");
  if (finalize_rounds < 1) return bad("finalize_rounds", finalize_rounds, ">= 1");
  if (corroboration_window < 0) return bad("corroboration_window", corroboration_window, ">= 0");
  return "";
}

}  // namespace arbor
