// Ordering and symbolic elimination of the re-eliminated top of a Bayes tree: a constrained
// CCOLAMD ordering (Davis et al., "A column approximate minimum degree ordering algorithm",
// 2004; constraint groups as in iSAM2, Kaess et al. 2012 §5) and the cliques (supernodes) that
// eliminating in that order produces (Kaess et al. 2012, Alg. 4 / §3.1).
#pragma once

#include <vector>

namespace arbor::bayestree {

/// Rows of a sparse structure in compressed form: row r holds vars[start[r] .. start[r+1]).
struct RowList {
  std::vector<int> start{0};
  std::vector<int> vars;

  int numRows() const { return static_cast<int>(start.size()) - 1; }
  void clear() {
    start.assign(1, 0);
    vars.clear();
  }
  void add(int v) { vars.push_back(v); }
  void endRow() { start.push_back(static_cast<int>(vars.size())); }
};

/// One clique of the symbolic elimination; variables are local indices 0..n−1.
struct SymbolicClique {
  std::vector<int> frontals;   ///< in elimination order
  std::vector<int> separator;  ///< in elimination order
  int parent = -1;             ///< index into EliminationPlan::cliques, −1 for a root
};

struct EliminationPlan {
  std::vector<int> order;               ///< position → local variable
  std::vector<int> position;            ///< local variable → position
  std::vector<SymbolicClique> cliques;  ///< children before parents
  std::vector<int> clique_of_variable;  ///< local variable → index into cliques
};

/// Columns 0..n−1 ordered by CCOLAMD; a column of smaller group comes first (constrained
/// ordering). rows may be empty; a row lists distinct columns.
std::vector<int> constrainedColamd(int n, const RowList& rows, const std::vector<int>& group);

/// As constrainedColamd, by CHOLMOD's nested dissection (METIS bisection, then constrained
/// minimum degree on the separator tree; George 1973): less fill and a bushier tree than
/// minimum degree on large, mesh-like problems. The variables of a larger group are then moved
/// after the others, keeping their order.
std::vector<int> constrainedNestedDissection(int n, const RowList& rows,
                                             const std::vector<int>& group);

/// Symbolic elimination of the structure `rows` over n variables in `order` (position →
/// variable), grouped into cliques: a variable joins the clique of its parent (the first
/// eliminated variable of its separator) when its separator equals that clique's variables.
EliminationPlan planElimination(int n, const RowList& rows, std::vector<int> order);

}  // namespace arbor::bayestree
