// Odometry-chain and breadth-first spanning-tree initialisation, and the dispatch.
#include "arbor_slam/core/initialization.h"

#include <algorithm>
#include <stdexcept>

#include "arbor_slam/core/initialization_internal.h"

namespace arbor {
namespace {

using init_detail::Adjacency;

/// The measurement of `edge` read from pose `from` to the other end: z or z⁻¹.
template <class G>
G measurementFrom(const RelativePoseEdge<G>& edge, int from) {
  return edge.i == from ? edge.measurement : edge.measurement.inverse();
}

/// Breadth-first placement from the gauge roots (poses in queue order, edges in file order).
/// With `follow_chain`, every pose placed also places its chain segment at once: the poses
/// k±1, k±2, ... linked by the first edge between consecutive dense indices.
template <class G>
std::vector<G> breadthFirstPlacement(const PoseGraph<G>& graph, bool follow_chain,
                                     const std::string& where) {
  init_detail::validateGraph(graph, where);
  const int n = graph.numPoses();
  if (n == 0) return {};
  const Adjacency adj = init_detail::buildAdjacency(graph);
  const init_detail::Roots<G> roots = init_detail::findRoots(graph, where);

  // chain[k] (k ≥ 1): the first edge in file order between k−1 and k, or −1.
  std::vector<int> chain(n, -1);
  if (follow_chain) {
    for (int id = 0; id < graph.numEdges(); ++id) {
      const auto& e = graph.edges[id];
      if (e.i - e.j == 1 || e.j - e.i == 1) {
        const int k = std::max(e.i, e.j);
        if (chain[k] < 0) chain[k] = id;
      }
    }
  }

  std::vector<G> x(n, G::Identity());
  std::vector<char> placed(n, 0);
  std::vector<int> queue;
  queue.reserve(n);
  auto place = [&](int k, const G& value) {
    x[k] = value;
    x[k].normalize();
    placed[k] = 1;
    queue.push_back(k);
  };
  auto extendChain = [&](int k) {
    if (!follow_chain) return;
    for (int m = k + 1; m < n && !placed[m] && chain[m] >= 0; ++m) {
      place(m, x[m - 1].compose(measurementFrom(graph.edges[chain[m]], m - 1)));
    }
    for (int m = k - 1; m >= 0 && !placed[m] && chain[m + 1] >= 0; --m) {
      place(m, x[m + 1].compose(measurementFrom(graph.edges[chain[m + 1]], m + 1)));
    }
  };

  for (std::size_t r = 0; r < roots.poses.size(); ++r) place(roots.poses[r], roots.values[r]);
  for (int r : roots.poses) extendChain(r);
  for (std::size_t head = 0; head < queue.size(); ++head) {
    const int p = queue[head];
    for (int a = adj.offsets[p]; a < adj.offsets[p + 1]; ++a) {
      const auto& e = graph.edges[adj.edge_ids[a]];
      const int o = e.i == p ? e.j : e.i;
      if (placed[o]) continue;
      place(o, x[p].compose(measurementFrom(e, p)));
      extendChain(o);
    }
  }
  for (int k = 0; k < n; ++k) {
    if (!placed[k]) throw init_detail::unreachablePose(graph, roots.first_gauge, k, where);
  }
  init_detail::alignToPositionPriors(graph, roots, &x);
  return x;
}

}  // namespace

std::string toString(InitMethod method) {
  switch (method) {
    case InitMethod::kOdometry:
      return "odometry";
    case InitMethod::kSpanningTree:
      return "spanning-tree";
    case InitMethod::kChordal:
      return "chordal";
    case InitMethod::kFile:
      return "file";
  }
  throw std::invalid_argument("toString: unknown InitMethod value " +
                              std::to_string(static_cast<int>(method)));
}

InitMethod parseInitMethod(const std::string& name) {
  for (InitMethod m : {InitMethod::kOdometry, InitMethod::kSpanningTree, InitMethod::kChordal,
                       InitMethod::kFile}) {
    if (name == toString(m)) return m;
  }
  throw std::invalid_argument("unknown initialisation method '" + name +
                              "' (expected odometry, spanning-tree, chordal or file)");
}

template <class G>
std::vector<G> odometryInitialization(const PoseGraph<G>& graph) {
  return breadthFirstPlacement(graph, /*follow_chain=*/true, "odometry initialisation");
}

template <class G>
std::vector<G> spanningTreeInitialization(const PoseGraph<G>& graph) {
  return breadthFirstPlacement(graph, /*follow_chain=*/false, "spanning-tree initialisation");
}

template <class G>
std::vector<G> initialize(const PoseGraph<G>& graph, InitMethod method) {
  switch (method) {
    case InitMethod::kOdometry:
      return odometryInitialization(graph);
    case InitMethod::kSpanningTree:
      return spanningTreeInitialization(graph);
    case InitMethod::kChordal:
      return chordalInitialization(graph);
    case InitMethod::kFile:
      if (!graph.has_initial_estimate) {
        throw std::invalid_argument(
            "file initialisation: the graph has no initial estimate (no VERTEX lines); use "
            "odometry, spanning-tree or chordal");
      }
      init_detail::validateGraph(graph, "file initialisation");
      return graph.poses;
  }
  throw std::invalid_argument("initialize: unknown InitMethod value " +
                              std::to_string(static_cast<int>(method)));
}

template std::vector<SE2> odometryInitialization(const PoseGraph<SE2>&);
template std::vector<SE3> odometryInitialization(const PoseGraph<SE3>&);
template std::vector<SE2> spanningTreeInitialization(const PoseGraph<SE2>&);
template std::vector<SE3> spanningTreeInitialization(const PoseGraph<SE3>&);
template std::vector<SE2> initialize(const PoseGraph<SE2>&, InitMethod);
template std::vector<SE3> initialize(const PoseGraph<SE3>&, InitMethod);

}  // namespace arbor
