// The smoother's factors and their linearisations: every factor added (core/factor.h), the
// factors of each variable, each factor's whitened linearisation in Hessian form, the threaded
// (re)linearisation, and the one rule of where a factor's terms enter the Bayes tree
// (assembledAt).
#pragma once

#include <array>
#include <deque>
#include <functional>
#include <vector>

#include <Eigen/Core>

#include "arbor_slam/bayestree/update_threads.h"
#include "arbor_slam/core/factor.h"

namespace arbor::bayestree {

template <class G>
class LinearizedFactors {
 public:
  static constexpr int D = G::kDoF;
  static constexpr int kMaxKeys = Factor<G>::kMaxKeys;
  using Mat = Eigen::Matrix<double, D, D>;
  using Vec = typename G::Tangent;

  /// One whitened factor ‖Σ_k A_k τ_k + r‖² over its keys in Hessian form: τᵀHτ − 2gᵀτ + rᵀr,
  /// H_kl = A_kᵀA_l, g_k = −A_kᵀr. H is kept as its lower triangle of blocks, H(k, l) for k ≥ l
  /// at block(k, l).
  struct LinearFactor {
    std::array<Mat, kMaxKeys*(kMaxKeys + 1) / 2> H;
    std::array<Vec, kMaxKeys> g;
    static int block(int k, int l) { return k * (k + 1) / 2 + l; }
    /// H(k, l) for any k, l.
    Mat at(int k, int l) const { return k >= l ? H[block(k, l)] : H[block(l, k)].transpose(); }
  };

  std::vector<Factor<G>> factors;             ///< in the order added
  std::vector<std::vector<int>> var_factors;  ///< variable → its factors in the structure
  /// factor → 1 while it is in the structure (listed in var_factors): every factor of inlier
  /// weight > 0. A factor at weight 0 (a rejected loop closure, an edge taken back) is left out
  /// of the elimination altogether — no fill, no larger cliques — until it is re-admitted
  /// (docs/design.md, "Online robust smoothing").
  std::vector<char> attached;
  /// factor → its linearisation; a deque, so adding a factor never moves the others (a vector
  /// doubling would copy every linearisation in one update: 7 ms at 8192 SE(3) factors)
  std::deque<LinearFactor> lin;
  std::vector<int> stamp;  ///< factor → last update that listed it

  int numFactors() const { return static_cast<int>(factors.size()); }
  /// Before adding `more` factors: when they would more than double the factor array, it grows
  /// to exactly what they need (a map loaded in one update: 1.24 million SE(2) factors take
  /// 358 MB instead of doubling's 604, with no copy of the array on the way); otherwise the
  /// array's own doubling.
  void reserveFor(size_t more) {
    const size_t need = factors.size() + more;
    if (need <= 2 * factors.capacity()) return;
    factors.reserve(need);
    stamp.reserve(need);
    attached.reserve(need);
  }
  /// A new variable (no factors yet).
  void addVariable() { var_factors.emplace_back(); }
  /// Adds a factor (not yet linearised; attached iff its inlier weight is > 0); returns its
  /// index.
  int add(const Factor<G>& f);
  /// Removes the factors from index n on (the last ones added), taking them out of the
  /// structure: undoes add() back to n factors.
  void truncate(int n) {
    for (int f = numFactors() - 1; f >= n; --f) {
      detach(f);
      factors.pop_back();
      lin.pop_back();
      stamp.pop_back();
      attached.pop_back();
    }
  }
  /// Puts factor f into the structure (its keys' var_factors) or takes it out. No-op when it is
  /// there already / not there.
  void attach(int f);
  void detach(int f);

  /// lin[f] from factor f linearised at θ, scaled by its inlier weight (Factor::linearizeWeighted).
  void linearize(int f, const std::vector<G>& theta);
  /// The same into *out.
  void linearize(int f, const std::vector<G>& theta, LinearFactor* out) const;
  /// linearize(f, θ) for every f of `fs` (factors of your own: the ones that can fail), all or
  /// none: each into `staged` first, then copied into lin once every one succeeded. A failure
  /// (an exception of the factor's model, a non-finite or misshapen result) throws FactorError
  /// (core/factor_error.h) naming the first failing factor of `fs` and its poses' values, with
  /// lin untouched.
  void linearizeAllOrNone(const std::vector<int>& fs, const std::vector<G>& theta,
                          UpdateThreads* threads, std::vector<LinearFactor>* staged);
  /// linearize(f, θ) for every f of `fs`, in chunks shared among the threads when many, side by
  /// side with `alongside` (if any: a task that does not read the linearised factors).
  void linearizeAll(const std::vector<int>& fs, const std::vector<G>& theta, UpdateThreads* threads,
                    const std::function<void()>& alongside = {});

  /// Whether factor f is assembled into the clique whose slots are `slot` at its frontal v:
  /// every non-fixed key of f lies in the clique, and v is the first of them (the others were
  /// not eliminated before v). The one rule of where a factor's terms enter the tree.
  static bool assembledAt(const Factor<G>& f, int v, const std::vector<int>& slot,
                          const std::vector<char>& fixed) {
    const int a = slot[v];
    for (int k = 0; k < f.arity(); ++k) {
      const int o = f.key(k);
      if (o == v || fixed[o]) continue;
      if (slot[o] <= a) return false;  // below (in a child's cached factor), or added from o
    }
    return true;
  }
};

extern template class LinearizedFactors<SE2>;
extern template class LinearizedFactors<SE3>;

}  // namespace arbor::bayestree
