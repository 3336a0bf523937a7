// Helpers shared by the initialisation methods (core/initialization.cc,
// core/chordal_initialization.cc); not part of the public API.
#pragma once

#include <stdexcept>
#include <string>
#include <vector>

#include "core/pose_graph.h"

namespace arbor::init_detail {

/// Each pose's incident edges in file order, as compressed rows: the edges of pose k are
/// edge_ids[offsets[k] .. offsets[k+1]). Self-loops are left out.
struct Adjacency {
  std::vector<int> offsets;
  std::vector<int> edge_ids;
};

template <class G>
Adjacency buildAdjacency(const PoseGraph<G>& graph) {
  const int n = graph.numPoses();
  Adjacency adj;
  adj.offsets.assign(n + 1, 0);
  for (const auto& e : graph.edges) {
    if (e.i == e.j) continue;
    ++adj.offsets[e.i + 1];
    ++adj.offsets[e.j + 1];
  }
  for (int k = 0; k < n; ++k) adj.offsets[k + 1] += adj.offsets[k];
  adj.edge_ids.resize(adj.offsets[n]);
  std::vector<int> next(adj.offsets.begin(), adj.offsets.end() - 1);
  for (int id = 0; id < graph.numEdges(); ++id) {
    const auto& e = graph.edges[id];
    if (e.i == e.j) continue;
    adj.edge_ids[next[e.i]++] = id;
    adj.edge_ids[next[e.j]++] = id;
  }
  return adj;
}

/// Throws std::invalid_argument (prefixed by `where`) if the graph is malformed.
template <class G>
void validateGraph(const PoseGraph<G>& graph, const std::string& where) {
  const int n = graph.numPoses();
  if (graph.has_initial_estimate && static_cast<int>(graph.poses.size()) != n) {
    throw std::invalid_argument(where + ": the graph has " + std::to_string(n) + " ids but " +
                                std::to_string(graph.poses.size()) + " initial poses");
  }
  for (int id = 0; id < graph.numEdges(); ++id) {
    const auto& e = graph.edges[id];
    if (e.i < 0 || e.i >= n || e.j < 0 || e.j >= n) {
      throw std::invalid_argument(where + ": edge " + std::to_string(id) + " (" +
                                  std::to_string(e.i) + " → " + std::to_string(e.j) +
                                  ") refers to a pose index outside 0.." + std::to_string(n - 1));
    }
  }
  for (int k : graph.gaugeIndices()) {
    if (k < 0 || k >= n) {
      throw std::invalid_argument(where + ": gauge (fixed) pose index " + std::to_string(k) +
                                  " is outside 0.." + std::to_string(n - 1));
    }
  }
}

/// The poses whose value is given, in order: every gauge pose at its file value when the graph
/// has an initial estimate, else the first gauge pose at the identity. Empty for an empty graph.
template <class G>
std::vector<int> gaugeRoots(const PoseGraph<G>& graph) {
  std::vector<int> gauge = graph.gaugeIndices();
  if (gauge.empty()) return {};
  if (!graph.has_initial_estimate) return {gauge.front()};
  std::vector<int> roots;
  std::vector<char> seen(graph.numPoses(), 0);
  for (int k : gauge) {
    if (!seen[k]) roots.push_back(k);
    seen[k] = 1;
  }
  return roots;
}

template <class G>
G rootValue(const PoseGraph<G>& graph, int k) {
  return graph.has_initial_estimate ? graph.poses[k] : G::Identity();
}

/// The std::invalid_argument for a pose that no edge path links to the gauge.
template <class G>
std::invalid_argument unreachablePose(const PoseGraph<G>& graph, const std::vector<int>& roots,
                                      int k, const std::string& where) {
  return std::invalid_argument(where + ": the pose graph is not connected: pose " +
                               std::to_string(graph.ids[k]) +
                               " is not reachable through the edges from the gauge pose " +
                               std::to_string(graph.ids[roots.front()]));
}

/// Throws unreachablePose for the first pose (dense order) not reachable from the roots.
template <class G>
void requireConnected(const PoseGraph<G>& graph, const Adjacency& adj,
                      const std::vector<int>& roots, const std::string& where) {
  const int n = graph.numPoses();
  std::vector<char> seen(n, 0);
  std::vector<int> queue;
  queue.reserve(n);
  for (int r : roots) {
    seen[r] = 1;
    queue.push_back(r);
  }
  for (std::size_t head = 0; head < queue.size(); ++head) {
    const int p = queue[head];
    for (int a = adj.offsets[p]; a < adj.offsets[p + 1]; ++a) {
      const auto& e = graph.edges[adj.edge_ids[a]];
      const int o = e.i == p ? e.j : e.i;
      if (!seen[o]) {
        seen[o] = 1;
        queue.push_back(o);
      }
    }
  }
  for (int k = 0; k < n; ++k) {
    if (!seen[k]) throw unreachablePose(graph, roots, k, where);
  }
}

}  // namespace arbor::init_detail
