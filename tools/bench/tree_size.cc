#include "arbor/tools/bench/tree_size.h"

#include <chrono>

#include "arbor/bayestree/elimination_plan.h"
#include "arbor/core/se2.h"
#include "arbor/core/se3.h"
#include "arbor/tools/bench/format.h"

namespace arbor::bench {

template <class G>
std::vector<TreeSizeRow> treeSizes(const PoseGraph<G>& graph, const std::vector<double>& ratios) {
  constexpr int D = G::kDoF;
  // Variables: the poses but the gauge ones; a row per edge between two of them (the structure
  // the top elimination orders, bayestree/top_elimination.cc).
  std::vector<int> slot(static_cast<size_t>(graph.numPoses()), 0);
  for (int v : graph.gaugeIndices()) slot[static_cast<size_t>(v)] = -1;
  int n = 0;
  for (int& s : slot)
    if (s == 0) s = n++;
  bayestree::RowList rows;
  for (const auto& e : graph.edges) {
    const int i = slot[static_cast<size_t>(e.i)], j = slot[static_cast<size_t>(e.j)];
    if (i < 0 || j < 0 || i == j) continue;
    rows.add(i);
    rows.add(j);
    rows.endRow();
  }
  const std::vector<int> group(static_cast<size_t>(n), 0);
  std::vector<TreeSizeRow> out;
  for (const bool nested : {false, true}) {
    const auto t0 = std::chrono::steady_clock::now();
    const bayestree::EliminationPlan plan =
        bayestree::planElimination(n, rows,
                                   nested ? bayestree::constrainedNestedDissection(n, rows, group)
                                          : bayestree::constrainedColamd(n, rows, group));
    const double seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    for (double r : ratios) {
      TreeSizeRow row;
      row.ordering = nested ? "nested dissection" : "colamd";
      row.ordering_s = seconds;
      row.max_ratio = r;
      row.shape = bayestree::treeShape<D>(plan, r);
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

template std::vector<TreeSizeRow> treeSizes(const PoseGraph<SE2>&, const std::vector<double>&);
template std::vector<TreeSizeRow> treeSizes(const PoseGraph<SE3>&, const std::vector<double>&);

}  // namespace arbor::bench
