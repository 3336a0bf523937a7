// Per-edge robust choices for a graph file (NAME.choices beside NAME.g2o, read with
// `--edge-choices FILE`): one line per id pair, "FROM TO TRUST [KERNEL]", which applies to every
// edge of the file between FROM and TO, in either direction. TRUST: default | trusted | robust
// (core/edge_trust.h); KERNEL: default | tls | gm | cauchy | huber (default: the command's
// --kernel). '#' starts a comment; blank lines are skipped. A sidecar rather than a g2o record:
// the graph file stays what g2o and every other tool reads. A bad line is a FileError naming
// "path:line" and the value; two lines for one pair too.
#pragma once

#include <iosfwd>
#include <map>
#include <string>
#include <utility>

#include "arbor_slam/core/edge_trust.h"
#include "arbor_slam/core/gnc_solver.h"
#include "arbor_slam/core/pose_graph.h"
#include "arbor_slam/core/robust_kernel.h"
#include "arbor_slam/io/pose_graph_file.h"

namespace arbor {

struct EdgeChoice {
  EdgeTrust trust = EdgeTrust::kByRule;
  KernelKind kernel = KernelKind::kNone;  ///< kNone: the command's --kernel
  int line = 0;                           ///< where it was read (for messages)
};

/// Keyed by (min id, max id): the choice of every edge between the two, either direction.
using EdgeChoices = std::map<std::pair<Key, Key>, EdgeChoice>;

/// Reads choices; `name` is used in messages in place of the path. Throws FileError.
EdgeChoices readEdgeChoices(std::istream& in, const std::string& name);
EdgeChoices readEdgeChoicesFile(const std::string& path);

/// The choice for an edge between `from` and `to` (the default one when none is listed).
EdgeChoice edgeChoice(const EdgeChoices& choices, Key from, Key to);

/// Throws FileError "name:line: FROM TO names no edge of the graph" for a listed pair without
/// an edge in `graph`.
template <class G>
void checkEdgeChoices(const EdgeChoices& choices, const PoseGraph<G>& graph,
                      const std::string& name);

/// The choices for the robust batch (`arbor batch --robust --edge-choices`): GncOptions::trusted
/// and ::kernels, one per edge, and trust_odometry off. kByRule keeps the batch's rule (odometry,
/// |i − j| = 1 in dense indices, trusted when gnc->trust_odometry was on; a mark already in
/// gnc->trusted stays), kTrusted holds the edge at weight 1, kRobust judges it whatever its ids;
/// a kernel other than kNone is that edge's own.
template <class G>
void applyEdgeChoices(const EdgeChoices& choices, const PoseGraph<G>& graph, GncOptions* gnc);

}  // namespace arbor
