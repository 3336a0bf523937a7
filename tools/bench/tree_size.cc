#include "arbor/tools/bench/tree_size.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdlib>

#include "arbor/bayestree/elimination_plan.h"
#include "arbor/core/se2.h"
#include "arbor/core/se3.h"
#include "arbor/tools/bench/format.h"

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

// Nearest-rank percentile of a sorted sample.
double percentile(const std::vector<double>& sorted, double p) {
  if (sorted.empty()) return 0;
  const size_t rank = static_cast<size_t>(std::ceil(p / 100.0 * sorted.size()));
  return sorted[std::min(sorted.size() - 1, rank == 0 ? 0 : rank - 1)];
}

}  // namespace

template <class G>
std::vector<TreeSizeRow> treeSizes(const PoseGraph<G>& graph, const std::vector<double>& ratios) {
  constexpr int D = G::kDoF;
  const WholeGraph w = wholeGraph(graph);
  std::vector<TreeSizeRow> out;
  for (const bool nested : {false, true}) {
    const auto t0 = std::chrono::steady_clock::now();
    const bayestree::EliminationPlan p = plan(w, nested);
    const double seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    for (double r : ratios) {
      TreeSizeRow row;
      row.ordering = nested ? "nested dissection" : "colamd";
      row.ordering_s = seconds;
      row.max_ratio = r;
      row.shape = bayestree::treeShape<D>(p, r);
      out.push_back(row);
    }
  }
  return out;
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

template <class G>
std::vector<PathCostRow> lastTenthPathCosts(const PoseGraph<G>& graph) {
  constexpr int D = G::kDoF;
  const WholeGraph w = wholeGraph(graph);
  const int m = graph.numEdges();
  std::vector<PathCostRow> out;
  for (const bool nested : {false, true}) {
    const bayestree::EliminationPlan p = plan(w, nested);
    PathCostRow row;
    row.ordering = nested ? "nested dissection" : "colamd";
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
      const bayestree::PathCost c =
          bayestree::pathCost<D>(p, a < 0 ? b : a, b < 0 ? a : b, &seen, k);
      cliques.push_back(c.cliques);
      reelimination.push_back(c.reelimination_flops / 1e6);
      rank_update.push_back(c.rank_update_flops / 1e6);
      all_reelimination.push_back(c.reelimination_flops / 1e6);
      all_rank_update.push_back(c.rank_update_flops / 1e6);
      rewritten.push_back(c.rewritten_doubles * 8 / 1e6);
      all_rewritten.push_back(c.rewritten_doubles * 8 / 1e6);
    }
    for (auto* v : {&cliques, &reelimination, &rank_update, &rewritten, &all_reelimination,
                    &all_rank_update, &all_rewritten})
      std::sort(v->begin(), v->end());
    row.cliques_p50 = percentile(cliques, 50);
    row.cliques_max = percentile(cliques, 100);
    row.reelimination_p50 = percentile(reelimination, 50);
    row.reelimination_p99 = percentile(reelimination, 99);
    row.reelimination_max = percentile(reelimination, 100);
    row.rank_update_p50 = percentile(rank_update, 50);
    row.rank_update_p99 = percentile(rank_update, 99);
    row.rank_update_max = percentile(rank_update, 100);
    row.rewritten_mb_p50 = percentile(rewritten, 50);
    row.rewritten_mb_p99 = percentile(rewritten, 99);
    row.rewritten_mb_max = percentile(rewritten, 100);
    row.updates_reelimination_p99 = percentile(all_reelimination, 99);
    row.updates_rewritten_mb_p99 = percentile(all_rewritten, 99);
    row.updates_rank_update_p99 = percentile(all_rank_update, 99);
    out.push_back(row);
  }
  return out;
}

void printPathCostTable(std::ostream& out, const std::vector<PathCostRow>& rows) {
  out << "| ordering | updates | loop closures | cliques reached p50 / max | re-elimination MFlop "
         "p50 / p99 / max | rank update MFlop p50 / p99 / max | conditionals rewritten MB p50 / "
         "p99 "
         "/ max | every update's p99: re-elimination MFlop / rank update MFlop / rewritten MB "
         "|\n"
         "|---|---|---|---|---|---|---|---|\n";
  for (const PathCostRow& r : rows)
    out << "| " << r.ordering << " | " << r.updates << " | " << r.closures << " | "
        << fmt("%.0f", r.cliques_p50) << " / " << fmt("%.0f", r.cliques_max) << " | "
        << fmt("%.2f", r.reelimination_p50) << " / " << fmt("%.2f", r.reelimination_p99) << " / "
        << fmt("%.2f", r.reelimination_max) << " | " << fmt("%.2f", r.rank_update_p50) << " / "
        << fmt("%.2f", r.rank_update_p99) << " / " << fmt("%.2f", r.rank_update_max) << " | "
        << fmt("%.2f", r.rewritten_mb_p50) << " / " << fmt("%.2f", r.rewritten_mb_p99) << " / "
        << fmt("%.2f", r.rewritten_mb_max) << " | " << fmt("%.2f", r.updates_reelimination_p99)
        << " / " << fmt("%.2f", r.updates_rank_update_p99) << " / "
        << fmt("%.2f", r.updates_rewritten_mb_p99) << " |\n";
}

template std::vector<TreeSizeRow> treeSizes(const PoseGraph<SE2>&, const std::vector<double>&);
template std::vector<TreeSizeRow> treeSizes(const PoseGraph<SE3>&, const std::vector<double>&);
template std::vector<PathCostRow> lastTenthPathCosts(const PoseGraph<SE2>&);
template std::vector<PathCostRow> lastTenthPathCosts(const PoseGraph<SE3>&);

}  // namespace arbor::bench
