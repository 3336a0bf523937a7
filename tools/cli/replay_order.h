// The order in which `arbor replay` and `arbor publish` feed a file's edges: by max(i, j) of
// the pose ids, then file order.
#pragma once

#include <algorithm>
#include <numeric>
#include <vector>

#include "core/pose_graph.h"

namespace arbor::cli {

/// Edge indices grouped per update: one edge per group (`per_pose` false), or all the edges
/// that end at the same new pose max(i, j) (`per_pose` true).
template <class G>
std::vector<std::vector<int>> replayGroups(const PoseGraph<G>& graph, bool per_pose) {
  std::vector<int> order(graph.edges.size());
  std::iota(order.begin(), order.end(), 0);
  // Dense indices ascend with ids, so max over dense indices orders like max over ids.
  auto last = [&](int e) { return std::max(graph.edges[e].i, graph.edges[e].j); };
  std::stable_sort(order.begin(), order.end(), [&](int a, int b) { return last(a) < last(b); });
  std::vector<std::vector<int>> groups;
  for (int e : order) {
    if (per_pose && !groups.empty() && last(groups.back().back()) == last(e)) {
      groups.back().push_back(e);
    } else {
      groups.push_back({e});
    }
  }
  return groups;
}

}  // namespace arbor::cli
