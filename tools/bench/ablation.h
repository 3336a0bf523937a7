// Issue 52's ablation (`arbor bench robust --family NAMES --ablate RULE`): the robust layer's
// rules that RobustOptions can switch off, each by name, with the property it is there for, so
// that a family run with one rule off gives that rule's row of the ablation table
// (docs/benchmarks.md, "Ablation"). A rule whose removal changes nothing on the held-out seeds
// is to be deleted.
#pragma once

#include <functional>
#include <string>
#include <vector>

#include "arbor_slam/bayestree/online_gnc.h"

namespace arbor::bench {

struct Ablation {
  std::string name;      ///< "end-word", the --ablate value
  std::string field;     ///< the RobustOptions field(s) it sets, as written in the report
  std::string property;  ///< what the rule guarantees, one line
  std::function<void(RobustOptions*)> off;  ///< sets `field`
};

/// Every rule --ablate knows, in the order of the table.
const std::vector<Ablation>& ablations();

/// The rule named `name`; std::invalid_argument naming the value and the known names for any
/// other name.
const Ablation& ablation(const std::string& name);

/// `options` with rule `name` switched off (ablation(name).off); throws as ablation().
RobustOptions ablated(const std::string& name, RobustOptions options = {});

}  // namespace arbor::bench
