// The order in which `arbor replay` and `arbor publish` feed a file's edges: by max(i, j) of
// the pose ids, then file order; a pose's priors (pose priors, then position priors, each in
// file order) right after the edge that makes the pose known, and priors on poses no edge
// reaches after every edge: streamOrder for a publisher's flat stream, PriorSchedule for the
// replay, which feeds edges in update groups.
#pragma once

#include <algorithm>
#include <numeric>
#include <vector>

#include "arbor_slam/bayestree/online_smoother.h"
#include "arbor_slam/core/pose_graph.h"

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

/// Merges the first groups into one that holds at least `edges` edges (all of them when there
/// are fewer): a map of that many edges loaded in one update before the rest streams in.
/// edges ≤ 0: unchanged.
inline void mergeFirstGroups(std::vector<std::vector<int>>* groups, int edges) {
  if (edges <= 0 || groups->empty()) return;
  size_t k = 1;
  std::vector<int> first = std::move((*groups)[0]);
  while (static_cast<int>(first.size()) < edges && k < groups->size()) {
    first.insert(first.end(), (*groups)[k].begin(), (*groups)[k].end());
    ++k;
  }
  groups->erase(groups->begin() + 1, groups->begin() + static_cast<std::ptrdiff_t>(k));
  (*groups)[0] = std::move(first);
}

/// One prior of a graph: a pose prior (position = false) or a position prior, by index.
struct PriorRef {
  bool position = false;
  int index = 0;
};

/// The priors of each pose (dense index), pose priors first, each kind in file order.
class PriorSchedule {
 public:
  template <class G>
  explicit PriorSchedule(const PoseGraph<G>& graph) : by_pose_(graph.ids.size()) {
    for (int k = 0; k < static_cast<int>(graph.pose_priors.size()); ++k)
      by_pose_[graph.pose_priors[k].i].push_back({false, k});
    for (int k = 0; k < static_cast<int>(graph.position_priors.size()); ++k)
      by_pose_[graph.position_priors[k].i].push_back({true, k});
    any_ = graph.hasPriors();
  }
  bool any() const { return any_; }
  const std::vector<PriorRef>& of(int pose) const { return by_pose_[pose]; }

 private:
  std::vector<std::vector<PriorRef>> by_pose_;
  bool any_ = false;
};

/// Hands one of the graph's priors to the online smoother (by the pose's id).
template <class G>
EdgeResult feedPrior(const PoseGraph<G>& graph, const PriorRef& p, OnlineSmoother<G>& smoother) {
  if (p.position) {
    const auto& prior = graph.position_priors[p.index];
    return smoother.addPositionPrior(graph.ids[prior.i], prior.position, prior.information);
  }
  const auto& prior = graph.pose_priors[p.index];
  return smoother.addPosePrior(graph.ids[prior.i], prior.measurement, prior.information,
                               prior.offset);
}

/// One message of a file's stream: an edge, a pose prior or a position prior, by its index in
/// graph.edges, graph.pose_priors or graph.position_priors.
struct StreamStep {
  enum class Kind { kEdge, kPosePrior, kPositionPrior };
  Kind kind = Kind::kEdge;
  int index = 0;
};

/// The edges in replay order (replayGroups), each prior right after the first edge of that
/// order that touches its pose (the edge that introduces the pose to an online smoother);
/// after one edge its pose priors, then its position priors, each in file order. Priors on
/// poses that no edge touches come last, pose priors then position priors, in file order.
template <class G>
std::vector<StreamStep> streamOrder(const PoseGraph<G>& graph) {
  std::vector<int> edges;
  for (const auto& group : replayGroups(graph, false))
    edges.insert(edges.end(), group.begin(), group.end());
  // introduced[v]: the position in `edges` of the first edge touching pose v, −1 if none.
  std::vector<int> introduced(graph.ids.size(), -1);
  for (int k = static_cast<int>(edges.size()) - 1; k >= 0; --k) {
    introduced[graph.edges[edges[k]].i] = k;
    introduced[graph.edges[edges[k]].j] = k;
  }
  // after[k + 1]: the priors that follow edge k; after[0]: those no edge introduces.
  std::vector<std::vector<StreamStep>> after(edges.size() + 1);
  for (int p = 0; p < static_cast<int>(graph.pose_priors.size()); ++p)
    after[introduced[graph.pose_priors[p].i] + 1].push_back({StreamStep::Kind::kPosePrior, p});
  for (int p = 0; p < static_cast<int>(graph.position_priors.size()); ++p)
    after[introduced[graph.position_priors[p].i] + 1].push_back(
        {StreamStep::Kind::kPositionPrior, p});
  std::vector<StreamStep> order;
  order.reserve(edges.size() + graph.pose_priors.size() + graph.position_priors.size());
  for (size_t k = 0; k < edges.size(); ++k) {
    order.push_back({StreamStep::Kind::kEdge, edges[k]});
    order.insert(order.end(), after[k + 1].begin(), after[k + 1].end());
  }
  order.insert(order.end(), after[0].begin(), after[0].end());
  return order;
}

}  // namespace arbor::cli
