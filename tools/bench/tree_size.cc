#include "arbor_slam/tools/bench/tree_size.h"

#include <chrono>
#include <cstdlib>
#include <utility>

#include "arbor_slam/bayestree/elimination_plan.h"
#include "arbor_slam/core/se2.h"
#include "arbor_slam/core/se3.h"
#include "arbor_slam/tools/bench/format.h"

namespace arbor::bench {

namespace {

// Variables: the poses but the gauge ones; a row per edge between two of them (the structure
// the top elimination orders, bayestree/top_elimination.cc).
struct WholeGraph {
  int n = 0;
  std::vector<int> slot;  ///< dense pose index → variable, −1 for a gauge pose
  bayestree::RowList rows;
};

template <class G>
WholeGraph wholeGraph(const PoseGraph<G>& graph) {
  WholeGraph w;
  w.slot.assign(static_cast<size_t>(graph.numPoses()), 0);
  for (int v : graph.gaugeIndices()) w.slot[static_cast<size_t>(v)] = -1;
  for (int& s : w.slot)
    if (s == 0) s = w.n++;
  for (const auto& e : graph.edges) {
    const int i = w.slot[static_cast<size_t>(e.i)], j = w.slot[static_cast<size_t>(e.j)];
    if (i < 0 || j < 0 || i == j) continue;
    w.rows.add(i);
    w.rows.add(j);
    w.rows.endRow();
  }
  return w;
}

bayestree::EliminationPlan plan(const WholeGraph& w, bool nested) {
  const std::vector<int> group(static_cast<size_t>(w.n), 0);
  return bayestree::planElimination(w.n, w.rows,
                                    nested
                                        ? bayestree::constrainedNestedDissection(w.n, w.rows, group)
                                        : bayestree::constrainedColamd(w.n, w.rows, group));
}

}  // namespace

namespace {

// The last tenth's path costs in the tree of plan p.
template <class G>
PathCostRow pathCosts(const PoseGraph<G>& graph, const WholeGraph& w,
                      const bayestree::EliminationPlan& p) {
  constexpr int D = G::kDoF;
  const int m = graph.numEdges();
  PathCostRow row;
  std::vector<int> seen(p.cliques.size(), -1);
  std::vector<double> cliques, reelimination, rank_update, rewritten, all_reelimination,
      all_rank_update, all_rewritten;
  for (int k = m - m / 10; k < m; ++k) {
    const auto& e = graph.edges[static_cast<size_t>(k)];
    ++row.updates;
    const int a = w.slot[static_cast<size_t>(e.i)], b = w.slot[static_cast<size_t>(e.j)];
    if (std::abs(e.i - e.j) == 1 || (a < 0 && b < 0)) {
      all_reelimination.push_back(0);
      all_rank_update.push_back(0);
      all_rewritten.push_back(0);
      continue;
    }
    ++row.closures;
    const bayestree::PathCost c = bayestree::pathCost<D>(p, a < 0 ? b : a, b < 0 ? a : b, &seen, k);
    cliques.push_back(c.cliques);
    reelimination.push_back(c.reelimination_flops / 1e6);
    rank_update.push_back(c.rankUpdateFlops<D>() / 1e6);
    rewritten.push_back(c.rewritten_doubles * 8 / 1e6);
    all_reelimination.push_back(reelimination.back());
    all_rank_update.push_back(rank_update.back());
    all_rewritten.push_back(rewritten.back());
  }
  row.cliques = summarizeLatency(std::move(cliques));
  row.reelimination_mflop = summarizeLatency(std::move(reelimination));
  row.rank_update_mflop = summarizeLatency(std::move(rank_update));
  row.rewritten_mb = summarizeLatency(std::move(rewritten));
  row.updates_reelimination_mflop = summarizeLatency(std::move(all_reelimination));
  row.updates_rank_update_mflop = summarizeLatency(std::move(all_rank_update));
  row.updates_rewritten_mb = summarizeLatency(std::move(all_rewritten));
  return row;
}

}  // namespace

template <class G>
TreeReport treeReport(const PoseGraph<G>& graph, const std::vector<double>& ratios) {
  constexpr int D = G::kDoF;
  const WholeGraph w = wholeGraph(graph);
  TreeReport report;
  for (const bool nested : {false, true}) {
    const char* ordering = nested ? "nested dissection" : "colamd";
    const auto t0 = std::chrono::steady_clock::now();
    const bayestree::EliminationPlan p = plan(w, nested);
    const double seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    for (double r : ratios) {
      TreeSizeRow row;
      row.ordering = ordering;
      row.ordering_s = seconds;
      row.max_ratio = r;
      row.shape = bayestree::treeShape<D>(p, r);
      report.sizes.push_back(row);
    }
    report.paths.push_back(pathCosts(graph, w, p));
    report.paths.back().ordering = ordering;
  }
  return report;
}

void printTreeSizeTable(std::ostream& out, const std::vector<TreeSizeRow>& rows, int poses) {
  out << "| ordering | ordering s | cliques | factorisation MFlop | max F | max S | cached-factor "
         "ratio | cliques without | conditionals MB | cached factors MB | dropped MB | tree MB | "
         "KB / pose |\n"
         "|---|---|---|---|---|---|---|---|---|---|---|---|---|\n";
  for (const TreeSizeRow& r : rows) {
    const auto& s = r.shape;
    const double mb = 8.0 / 1e6;
    out << "| " << r.ordering << " | " << fmt("%.2f", r.ordering_s) << " | " << s.cliques << " | "
        << fmt("%.0f", s.flops / 1e6) << " | " << s.max_frontal_dim << " | " << s.max_separator_dim
        << " | " << (r.max_ratio > 0 ? fmt("%g", r.max_ratio) : "all kept") << " | "
        << s.cliques_without_cached << " | " << fmt("%.0f", s.conditional_doubles * mb) << " | "
        << fmt("%.0f", s.cached_doubles * mb) << " | " << fmt("%.0f", s.dropped_doubles * mb)
        << " | " << fmt("%.0f", s.doubles() * mb) << " | "
        << fmt("%.2f", poses > 0 ? s.doubles() * 8.0 / 1e3 / poses : 0.0) << " |\n";
  }
}

void printPathCostTable(std::ostream& out, const std::vector<PathCostRow>& rows) {
  auto threePercentiles = [](const LatencySummary& l) {
    return fmt("%.2f", l.p50) + " / " + fmt("%.2f", l.p99) + " / " + fmt("%.2f", l.max);
  };
  out << "| ordering | updates | loop closures | cliques reached p50 / max | re-elimination MFlop "
         "p50 / p99 / max | rank update MFlop p50 / p99 / max | conditionals rewritten MB p50 / "
         "p99 "
         "/ max | every update's p99: re-elimination MFlop / rank update MFlop / rewritten MB "
         "|\n"
         "|---|---|---|---|---|---|---|---|\n";
  for (const PathCostRow& r : rows)
    out << "| " << r.ordering << " | " << r.updates << " | " << r.closures << " | "
        << fmt("%.0f", r.cliques.p50) << " / " << fmt("%.0f", r.cliques.max) << " | "
        << threePercentiles(r.reelimination_mflop) << " | " << threePercentiles(r.rank_update_mflop)
        << " | " << threePercentiles(r.rewritten_mb) << " | "
        << fmt("%.2f", r.updates_reelimination_mflop.p99) << " / "
        << fmt("%.2f", r.updates_rank_update_mflop.p99) << " / "
        << fmt("%.2f", r.updates_rewritten_mb.p99) << " |\n";
}

template TreeReport treeReport(const PoseGraph<SE2>&, const std::vector<double>&);
template TreeReport treeReport(const PoseGraph<SE3>&, const std::vector<double>&);

}  // namespace arbor::bench
