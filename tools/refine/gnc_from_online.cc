#include "arbor_slam/tools/refine/gnc_from_online.h"

#include <algorithm>
#include <stdexcept>
#include <string>

namespace arbor::refine {

OnlineClassification onlineBounds(double c2_in_use, double c2_at_end, double recheck_margin) {
  OnlineClassification out;
  out.c2 = recheck_margin * c2_in_use;
  out.c2_take_back = c2_at_end > 0 ? std::min(c2_in_use, c2_at_end) : c2_in_use;
  return out;
}

template <class G>
GncFromOnline solveGncFromOnline(const PoseGraph<G>& graph, GncOptions options,
                                 const OnlineClassification& online, std::vector<G>* poses) {
  const int m = graph.numEdges();
  if (!online.held_out.empty() && online.held_out.size() != static_cast<size_t>(m)) {
    throw std::invalid_argument("solveGncFromOnline: " + std::to_string(online.held_out.size()) +
                                " marks for " + std::to_string(m) + " edges");
  }
  GncFromOnline out;
  const bool at_bound = online.c2 > 0;
  if (at_bound) options.threshold = online.c2;
  options.known_outliers.assign(static_cast<size_t>(m), 0);
  std::vector<char> backed(static_cast<size_t>(m), 0);
  for (int k = 0; k < m; ++k) {
    if (trustedEdge(graph, options, k)) continue;
    const bool held_out = !online.held_out.empty() && online.held_out[static_cast<size_t>(k)];
    options.known_outliers[k] = held_out;
    out.known_outliers += held_out;
    const auto& e = graph.edges[static_cast<size_t>(k)];
    backed[k] =
        at_bound && !held_out &&
        e.cost((*poses)[static_cast<size_t>(e.i)], (*poses)[static_cast<size_t>(e.j)]) > online.c2;
    out.kept_beyond += backed[k];
  }
  if (out.kept_beyond > 0) {
    if (options.trusted.empty()) options.trusted.assign(static_cast<size_t>(m), 0);
    for (int k = 0; k < m; ++k) options.trusted[k] |= backed[k];
  }
  out.gnc = solveGnc(graph, poses, options);
  if (!out.gnc.cancelled) {
    const double bound = online.c2_take_back > 0 ? online.c2_take_back : out.gnc.threshold;
    out.readmitted = readmitFitting(graph, &out.gnc, poses, bound, options.outer);
  }
  return out;
}

template GncFromOnline solveGncFromOnline(const PoseGraph<SE2>&, GncOptions,
                                          const OnlineClassification&, std::vector<SE2>*);
template GncFromOnline solveGncFromOnline(const PoseGraph<SE3>&, GncOptions,
                                          const OnlineClassification&, std::vector<SE3>*);

}  // namespace arbor::refine
