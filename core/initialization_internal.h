// Helpers shared by the initialisation methods (core/initialization.cc,
// core/chordal_initialization.cc); not part of the public API.
#pragma once

#include <algorithm>
#include <cmath>
#include <numeric>
#include <stdexcept>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <Eigen/LU>

#include "arbor_slam/core/gauge.h"
#include "arbor_slam/core/pose_graph.h"
#include "arbor_slam/core/rigid_alignment.h"

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
  const auto checkPriors = [&](const auto& priors, const char* what) {
    for (std::size_t k = 0; k < priors.size(); ++k) {
      if (priors[k].i < 0 || priors[k].i >= n) {
        throw std::invalid_argument(where + ": " + what + " " + std::to_string(k) +
                                    " is on pose index " + std::to_string(priors[k].i) +
                                    ", outside 0.." + std::to_string(n - 1));
      }
    }
  };
  checkPriors(graph.pose_priors, "pose prior");
  checkPriors(graph.position_priors, "position prior");
  for (int k : graph.gaugeIndices()) {
    if (k < 0 || k >= n) {
      throw std::invalid_argument(where + ": gauge (fixed) pose index " + std::to_string(k) +
                                  " is outside 0.." + std::to_string(n - 1));
    }
  }
}

/// A pose from a rotation matrix and a translation.
inline SE2 makePose(const Eigen::Matrix2d& R, const Eigen::Vector2d& t) {
  return SE2(t, std::atan2(R(1, 0), R(0, 0)));
}
inline SE3 makePose(const Eigen::Matrix3d& R, const Eigen::Vector3d& t) {
  return SE3(Eigen::Quaterniond(R), t);
}

/// Where the initial guess starts: the root poses with their values (placed first, in order),
/// each pose's connected component (by edges; its lowest dense index), and which components are
/// aligned onto their position priors once the guess is computed.
template <class G>
struct Roots {
  std::vector<int> poses;
  std::vector<G> values;
  std::vector<int> component;  ///< per pose
  std::vector<char> align;     ///< per component (indexed by its lowest pose)
  int first_gauge = -1;        ///< the first gauge pose (for messages), −1 if none
};

/// The std::invalid_argument for a pose that no edge path links to the gauge.
template <class G>
std::invalid_argument unreachablePose(const PoseGraph<G>& graph, int first_gauge, int k,
                                      const std::string& where) {
  const std::string from =
      first_gauge < 0 ? std::string(
                            " is not reachable through the edges from a gauge "
                            "pose nor anchored by priors")
                      : " is not reachable through the edges from the gauge pose " +
                            std::to_string(graph.ids[first_gauge]) + " nor anchored by priors";
  return std::invalid_argument(where + ": the pose graph is not connected: pose " +
                               std::to_string(graph.ids[k]) + from);
}

/// The roots of every component, found in this order (core/initialization.h):
/// - a component holding gauge poses (graph.gaugeIndices()): every one of them at its file value
///   when the graph has an initial estimate, else its first gauge pose at the value of a pose
///   prior on it (the first in file order), or at the identity and then aligned;
/// - a component whose priors fix its gauge: the lowest pose with a pose prior, at that prior's
///   value z·o⁻¹; without pose priors, its lowest pose at the identity, then aligned;
/// - any other component: std::invalid_argument naming its lowest pose (unreachablePose).
template <class G>
Roots<G> findRoots(const PoseGraph<G>& graph, const std::string& where) {
  const int n = graph.numPoses();
  Roots<G> roots;
  roots.component.resize(n);
  std::iota(roots.component.begin(), roots.component.end(), 0);
  auto root = [&](int v) {
    std::vector<int>& parent = roots.component;
    while (parent[v] != v) v = parent[v] = parent[parent[v]];
    return v;
  };
  for (const auto& e : graph.edges) {
    const int a = root(e.i), b = root(e.j);
    if (a != b) roots.component[std::max(a, b)] = std::min(a, b);
  }
  for (int v = 0; v < n; ++v) roots.component[v] = root(v);
  const std::vector<int>& comp = roots.component;
  roots.align.assign(n, 0);

  // The first pose prior on each pose (file order), −1 if none.
  std::vector<int> pose_prior(n, -1);
  for (int k = static_cast<int>(graph.pose_priors.size()) - 1; k >= 0; --k)
    pose_prior[graph.pose_priors[k].i] = k;
  auto priorValue = [&](int v) {
    const auto& p = graph.pose_priors[pose_prior[v]];
    return p.measurement.compose(p.offset.inverse());
  };

  std::vector<char> rooted(n, 0);  // per component
  const std::vector<int> gauge = graph.gaugeIndices();
  std::vector<char> seen(n, 0);
  for (int k : gauge) {
    if (seen[k]) continue;
    seen[k] = 1;
    if (roots.first_gauge < 0) roots.first_gauge = k;
    const int c = comp[k];
    if (graph.has_initial_estimate) {
      roots.poses.push_back(k);
      roots.values.push_back(graph.poses[k]);
    } else if (!rooted[c]) {
      roots.poses.push_back(k);
      roots.values.push_back(pose_prior[k] >= 0 ? priorValue(k) : G::Identity());
      roots.align[c] = pose_prior[k] < 0;
    }
    rooted[c] = 1;
  }

  std::vector<GaugeInformation<G>> info(n);
  for (const auto& p : graph.pose_priors) info[comp[p.i]].addPosePrior();
  for (const auto& p : graph.position_priors)
    info[comp[p.i]].addPositionPrior(p.position, p.information);
  std::vector<int> lowest_with_prior(n, -1);  // per component
  for (int v = n - 1; v >= 0; --v)
    if (pose_prior[v] >= 0) lowest_with_prior[comp[v]] = v;
  for (int c = 0; c < n; ++c) {
    if (comp[c] != c || rooted[c]) continue;
    if (!info[c].fixesGauge()) throw unreachablePose(graph, roots.first_gauge, c, where);
    const int v = lowest_with_prior[c];
    roots.poses.push_back(v >= 0 ? v : c);
    roots.values.push_back(v >= 0 ? priorValue(v) : G::Identity());
    roots.align[c] = v < 0;
    rooted[c] = 1;
  }
  return roots;
}

/// One component's position priors, for its rigid alignment: the positions qₖ of their poses,
/// the priors' positions pₖ, their weights wₖ and what they fix of the gauge.
template <class G>
struct AlignmentPoints {
  std::vector<typename G::Translation> q, p;
  std::vector<double> w;
  GaugeInformation<G> info;
};

/// Moves every component marked in roots.align rigidly onto its position priors: x ↦ T x with
/// T = (R, t) minimising Σ wₖ ‖R qₖ + t − pₖ‖² over the priors k of the component, qₖ the
/// position of its pose in *x, pₖ the prior's position, wₖ = kDim / tr(Ωₖ⁻¹) (the isotropic
/// precision). When the priors fix the rotation (GaugeInformation: ≥ 2 distinct positions in 2D,
/// ≥ 3 non-collinear in 3D), T is the weighted Kabsch / Umeyama fit of core/rigid_alignment.h;
/// otherwise R = I and t = p̄ − q̄ (weighted centroids q̄ = Σ wq / Σ w, p̄ likewise).
template <class G>
void alignToPositionPriors(const PoseGraph<G>& graph, const Roots<G>& roots, std::vector<G>* x) {
  constexpr int d = G::kDim;
  using MatD = Eigen::Matrix<double, d, d>;
  using VecD = Eigen::Matrix<double, d, 1>;
  const int n = graph.numPoses();
  if (graph.position_priors.empty()) return;
  std::vector<AlignmentPoints<G>> points(n);  // per component (indexed by its lowest pose)
  for (const auto& prior : graph.position_priors) {
    const int c = roots.component[prior.i];
    if (!roots.align[c]) continue;
    AlignmentPoints<G>& s = points[c];
    s.q.push_back((*x)[prior.i].translation());
    s.p.push_back(prior.position);
    s.w.push_back(d / prior.information.inverse().trace());
    s.info.addPositionPrior(prior.position, prior.information);
  }
  std::vector<G> transform(n, G::Identity());
  std::vector<char> moved(n, 0);
  for (int c = 0; c < n; ++c) {
    const AlignmentPoints<G>& s = points[c];
    double w = 0;
    VecD q = VecD::Zero(), p = VecD::Zero();
    for (std::size_t k = 0; k < s.w.size(); ++k) {
      w += s.w[k];
      q += s.w[k] * s.q[k];
      p += s.w[k] * s.p[k];
    }
    if (!(w > 0)) continue;
    transform[c] = s.info.fixesGauge() ? rigidAlignment<G>(s.q, s.p, s.w)
                                       : makePose(MatD::Identity(), VecD(p / w - q / w));
    moved[c] = 1;
  }
  for (int v = 0; v < n; ++v) {
    if (!moved[roots.component[v]]) continue;
    (*x)[v] = transform[roots.component[v]].compose((*x)[v]);
    (*x)[v].normalize();
  }
}

/// Throws unreachablePose for the first pose (dense order) not reachable from the roots.
template <class G>
void requireConnected(const PoseGraph<G>& graph, const Adjacency& adj, const Roots<G>& roots,
                      const std::string& where) {
  const int n = graph.numPoses();
  std::vector<char> seen(n, 0);
  std::vector<int> queue;
  queue.reserve(n);
  for (int r : roots.poses) {
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
    if (!seen[k]) throw unreachablePose(graph, roots.first_gauge, k, where);
  }
}

}  // namespace arbor::init_detail
