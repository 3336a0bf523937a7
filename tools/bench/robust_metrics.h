// How `arbor bench robust` judges an estimate of a graph with planted false loop closures
// (issue 14): against the base file (the graph without them) and the labels of the planted edges.
//
//   F_clean   = Σ eᵀΩe over the base file's edges and priors at the estimate (the estimate's
//               poses taken by id), set against the clean F* of reference/optimum.tsv;
//   ATE       = √(1/n Σₖ ‖T pₖ − p*ₖ‖²), pₖ the estimate's positions, p*ₖ the clean optimum's,
//               T the rigid move minimising that sum (core/rigid_alignment.h, unit weights);
//   precision = |rejected edges whose pair is labelled| / |rejected edges|,
//   recall    = |labelled pairs some rejected edge has| / |labelled pairs|,
//               pairs unordered ({i, j} = {j, i}), ids as the files write them.
#pragma once

#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>
#include <vector>

#include "arbor_slam/core/pose_graph.h"
#include "arbor_slam/core/rigid_alignment.h"
#include "arbor_slam/io/labels_file.h"

namespace arbor::bench {

/// Precision and recall of a rejected set against the labels.
struct RejectionScore {
  int rejected = 0;        ///< rejected edges
  int labels = 0;          ///< distinct labelled pairs
  int true_positives = 0;  ///< rejected edges whose pair is labelled
  int labels_found = 0;    ///< labelled pairs that some rejected edge has
  double precision = std::numeric_limits<double>::quiet_NaN();  ///< NaN when nothing rejected
  double recall = std::numeric_limits<double>::quiet_NaN();     ///< NaN when there are no labels
};

/// Scores `rejected` (one pair per rejected edge) against `labels`, pairs unordered.
RejectionScore scoreRejections(const std::vector<LabelPair>& rejected,
                               const std::vector<LabelPair>& labels);

/// The pairs (file ids) of the edges of `graph` marked in `rejected` (one mark per edge).
/// Throws std::invalid_argument if the sizes differ.
template <class G>
std::vector<LabelPair> rejectedPairs(const PoseGraph<G>& graph, const std::vector<char>& rejected) {
  if (rejected.size() != graph.edges.size())
    throw std::invalid_argument("rejectedPairs: " + std::to_string(rejected.size()) +
                                " marks for " + std::to_string(graph.edges.size()) + " edges");
  std::vector<LabelPair> pairs;
  for (size_t k = 0; k < rejected.size(); ++k) {
    if (rejected[k]) pairs.emplace_back(graph.ids[graph.edges[k].i], graph.ids[graph.edges[k].j]);
  }
  return pairs;
}

/// The poses `estimate` (one per pose of `from`) gives the poses of `onto`, matched by id, in
/// onto's dense order. Throws std::invalid_argument naming the first id of `onto` that `from`
/// lacks, or on a size mismatch.
template <class G>
std::vector<G> posesByIds(const PoseGraph<G>& from, const std::vector<G>& estimate,
                          const PoseGraph<G>& onto) {
  if (estimate.size() != from.ids.size())
    throw std::invalid_argument("posesByIds: " + std::to_string(estimate.size()) +
                                " poses for a graph of " + std::to_string(from.ids.size()));
  std::vector<G> out;
  out.reserve(onto.ids.size());
  for (const Key id : onto.ids) {
    const auto it = from.index.find(id);
    if (it == from.index.end())
      throw std::invalid_argument("posesByIds: pose " + std::to_string(id) +
                                  " of the base graph is not in the estimate");
    out.push_back(estimate[it->second]);
  }
  return out;
}

/// F over `base`'s edges and priors at `estimate` (one per pose of `graph`), taken by id.
template <class G>
double cleanObjective(const PoseGraph<G>& base, const PoseGraph<G>& graph,
                      const std::vector<G>& estimate) {
  return objective(base, posesByIds(graph, estimate, base));
}

/// RMS position error of `estimate` against `reference` (same poses, same order) after the
/// rigid alignment of the estimate's positions onto the reference's. Throws
/// std::invalid_argument on a size mismatch; 0 for no poses.
template <class G>
double alignedAte(const std::vector<G>& estimate, const std::vector<G>& reference) {
  if (estimate.size() != reference.size())
    throw std::invalid_argument("alignedAte: " + std::to_string(estimate.size()) +
                                " poses against " + std::to_string(reference.size()));
  if (estimate.empty()) return 0;
  std::vector<typename G::Translation> q, p;
  q.reserve(estimate.size());
  p.reserve(estimate.size());
  for (size_t k = 0; k < estimate.size(); ++k) {
    q.push_back(estimate[k].translation());
    p.push_back(reference[k].translation());
  }
  const G T = rigidAlignment<G>(q, p, std::vector<double>(q.size(), 1.0));
  double sum = 0;
  for (size_t k = 0; k < q.size(); ++k) sum += (T.act(q[k]) - p[k]).squaredNorm();
  return std::sqrt(sum / static_cast<double>(q.size()));
}

}  // namespace arbor::bench
