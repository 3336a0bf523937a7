#include "arbor_slam/bayestree/elimination_plan.h"

#include <cholmod.h>

#include <algorithm>
#include <numeric>
#include <stdexcept>
#include <string>

#include <ccolamd.h>

namespace arbor::bayestree {

std::vector<int> constrainedColamd(int n, const RowList& rows, const std::vector<int>& group) {
  if (static_cast<int>(group.size()) != n)
    throw std::invalid_argument("constrainedColamd: group size " + std::to_string(group.size()) +
                                " != n " + std::to_string(n));
  std::vector<int> order(n);
  std::iota(order.begin(), order.end(), 0);
  const int n_row = rows.numRows();
  const int nnz = static_cast<int>(rows.vars.size());
  if (n <= 2 || nnz == 0) {
    std::stable_sort(order.begin(), order.end(), [&](int a, int b) { return group[a] < group[b]; });
    return order;
  }
  // CCOLAMD wants the column-major (CSC) structure: row indices per column.
  std::vector<int> p(n + 1, 0);
  for (int v : rows.vars) ++p[v + 1];
  for (int c = 0; c < n; ++c) p[c + 1] += p[c];
  const size_t alen = ccolamd_recommended(nnz, n_row, n);
  if (alen == 0) throw std::runtime_error("constrainedColamd: ccolamd_recommended failed");
  std::vector<int> A(alen);
  std::vector<int> fill(p.begin(), p.end() - 1);
  for (int r = 0; r < n_row; ++r)
    for (int k = rows.start[r]; k < rows.start[r + 1]; ++k) A[fill[rows.vars[k]]++] = r;
  double knobs[CCOLAMD_KNOBS];
  int stats[CCOLAMD_STATS];
  ccolamd_set_defaults(knobs);
  std::vector<int> cmember(group);
  if (!ccolamd(n_row, n, static_cast<int>(alen), A.data(), p.data(), knobs, stats, cmember.data()))
    throw std::runtime_error("constrainedColamd: ccolamd failed with status " +
                             std::to_string(stats[CCOLAMD_STATUS]));
  order.assign(p.begin(), p.begin() + n);
  return order;
}

std::vector<int> constrainedNestedDissection(int n, const RowList& rows,
                                             const std::vector<int>& group) {
  if (static_cast<int>(group.size()) != n)
    throw std::invalid_argument("constrainedNestedDissection: group size " +
                                std::to_string(group.size()) + " != n " + std::to_string(n));
  const int n_row = rows.numRows();
  const int nnz = static_cast<int>(rows.vars.size());
  if (n <= 64 || nnz == 0) return constrainedColamd(n, rows, group);
  // CHOLMOD orders A·Aᵀ for the n×n_row pattern A whose column r is row r of `rows`.
  cholmod_common common;
  cholmod_start(&common);
  std::vector<int> order(n);
  cholmod_sparse* A = cholmod_allocate_sparse(n, n_row, nnz, /*sorted=*/0, /*packed=*/1,
                                              /*stype=*/0, CHOLMOD_PATTERN, &common);
  bool ok = A != nullptr;
  if (ok) {
    int* Ap = static_cast<int*>(A->p);
    int* Ai = static_cast<int*>(A->i);
    for (int r = 0; r <= n_row; ++r) Ap[r] = rows.start[r];
    std::copy(rows.vars.begin(), rows.vars.end(), Ai);
    std::vector<int> cparent(n), cmember(n);
    ok = cholmod_nested_dissection(A, nullptr, 0, order.data(), cparent.data(), cmember.data(),
                                   &common) >= 0 &&
         common.status == CHOLMOD_OK;
  }
  cholmod_free_sparse(&A, &common);
  cholmod_finish(&common);
  if (!ok) return constrainedColamd(n, rows, group);  // e.g. METIS out of memory
  // The constraint: variables of a larger group after the others (in their order).
  std::stable_sort(order.begin(), order.end(), [&](int a, int b) { return group[a] < group[b]; });
  return order;
}

EliminationPlan planElimination(int n, const RowList& rows, std::vector<int> order) {
  EliminationPlan plan;
  plan.order = std::move(order);
  if (static_cast<int>(plan.order.size()) != n)
    throw std::invalid_argument("planElimination: order size != n");
  plan.position.assign(n, -1);
  for (int k = 0; k < n; ++k) plan.position[plan.order[k]] = k;

  // Each row goes to the position of its first eliminated variable.
  std::vector<int> row_head(n, -1), row_next(rows.numRows(), -1);
  for (int r = 0; r < rows.numRows(); ++r) {
    int first = n;
    for (int k = rows.start[r]; k < rows.start[r + 1]; ++k)
      first = std::min(first, plan.position[rows.vars[k]]);
    if (first == n) continue;
    row_next[r] = row_head[first];
    row_head[first] = r;
  }
  // Symbolic elimination: the separator of position k is the union of its rows and of the
  // separators of the positions whose parent it is, minus k itself.
  // Separators are stored one after another in sep_vars (position k: sep_start[k] ..
  // sep_start[k + 1]).
  std::vector<int> sep_start(n + 1, 0), sep_vars;
  sep_vars.reserve(4 * static_cast<size_t>(n));
  std::vector<int> child_head(n, -1), child_next(n, -1), marker(n, -1);
  // (A separator is kept unsorted: only its size, its first position (the parent) and, for a
  // position that starts a clique, its sorted copy are needed below.)
  std::vector<int> sep_first(n, n);
  for (int k = 0; k < n; ++k) {
    const size_t begin = sep_vars.size();
    int first = n;
    marker[k] = k;
    for (int r = row_head[k]; r >= 0; r = row_next[r])
      for (int q = rows.start[r]; q < rows.start[r + 1]; ++q) {
        const int pos = plan.position[rows.vars[q]];
        if (marker[pos] != k) {
          marker[pos] = k;
          sep_vars.push_back(pos);
          first = std::min(first, pos);
        }
      }
    for (int c = child_head[k]; c >= 0; c = child_next[c])
      for (int q = sep_start[c]; q < sep_start[c + 1]; ++q) {
        const int pos = sep_vars[q];
        if (marker[pos] != k) {
          marker[pos] = k;
          sep_vars.push_back(pos);
          first = std::min(first, pos);
        }
      }
    sep_start[k + 1] = static_cast<int>(sep_vars.size());
    sep_first[k] = first;
    if (sep_vars.size() > begin) {
      child_next[k] = child_head[first];
      child_head[first] = k;
    }
  }
  // Supernodes, from the last position down: k joins its parent's clique when its separator is
  // exactly that clique's variables (frontals so far ∪ separator).
  std::vector<int> clique_of_pos(n, -1);
  std::vector<SymbolicClique> rev;  // frontals stored in reverse order while building
  for (int k = n - 1; k >= 0; --k) {
    const int* s = sep_vars.data() + sep_start[k];
    const size_t s_size = static_cast<size_t>(sep_start[k + 1] - sep_start[k]);
    if (s_size > 0) {
      const int c = clique_of_pos[sep_first[k]];
      if (rev[c].frontals.size() + rev[c].separator.size() == s_size) {
        rev[c].frontals.push_back(k);
        clique_of_pos[k] = c;
        continue;
      }
    }
    SymbolicClique clique;
    clique.frontals.push_back(k);
    clique.separator.assign(s, s + s_size);
    std::sort(clique.separator.begin(), clique.separator.end());
    clique.parent = s_size == 0 ? -1 : clique_of_pos[sep_first[k]];
    clique_of_pos[k] = static_cast<int>(rev.size());
    rev.push_back(std::move(clique));
  }
  // Reverse the clique list so children come before parents; positions → local variables.
  const int m = static_cast<int>(rev.size());
  plan.cliques.resize(m);
  for (int c = 0; c < m; ++c) {
    SymbolicClique& out = plan.cliques[m - 1 - c];
    SymbolicClique& in = rev[c];
    out.parent = in.parent < 0 ? -1 : m - 1 - in.parent;
    out.frontals.reserve(in.frontals.size());
    for (auto it = in.frontals.rbegin(); it != in.frontals.rend(); ++it)
      out.frontals.push_back(plan.order[*it]);
    out.separator.reserve(in.separator.size());
    for (int pos : in.separator) out.separator.push_back(plan.order[pos]);
  }
  plan.clique_of_variable.assign(n, -1);
  for (int k = 0; k < n; ++k) plan.clique_of_variable[plan.order[k]] = m - 1 - clique_of_pos[k];
  return plan;
}

}  // namespace arbor::bayestree
