#include "arbor_slam/tools/bench/robust_metrics.h"

#include <algorithm>
#include <set>

namespace arbor::bench {
namespace {

LabelPair unordered(const LabelPair& p) {
  return {std::min(p.first, p.second), std::max(p.first, p.second)};
}

}  // namespace

RejectionScore scoreRejections(const std::vector<LabelPair>& rejected,
                               const std::vector<LabelPair>& labels) {
  std::set<LabelPair> labelled;
  for (const LabelPair& l : labels) labelled.insert(unordered(l));
  std::set<LabelPair> found;
  RejectionScore s;
  s.rejected = static_cast<int>(rejected.size());
  s.labels = static_cast<int>(labelled.size());
  for (const LabelPair& r : rejected) {
    const LabelPair u = unordered(r);
    if (!labelled.count(u)) continue;
    ++s.true_positives;
    found.insert(u);
  }
  s.labels_found = static_cast<int>(found.size());
  if (s.rejected > 0) s.precision = static_cast<double>(s.true_positives) / s.rejected;
  if (s.labels > 0) s.recall = static_cast<double>(s.labels_found) / s.labels;
  return s;
}

}  // namespace arbor::bench
