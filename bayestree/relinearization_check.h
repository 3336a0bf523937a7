// Fluid relinearisation's check, IJRR 2012 Alg. 5 step 1, "Mark variables in Δ above threshold
// β: J = {Δ_j ∈ Δ | |Δ_j| ≥ β}" (|·|∞ on the translational and the rotational part, each against
// its β), over the variables in the tree. Only a variable solved since the last check can have
// crossed β (every other one was below it then, or relinearised and solved since), so the check
// reads those candidates only, unless Δ was set outside the solve (dogleg, relinearizeAll's
// halving, a swapped-in tree): then it scans every variable.
//
// Invariants: each candidate is listed once (its flag set); a check, or consume(), empties the
// list and clears every flag; mark() lists M in increasing order, as a scan of all would.
#pragma once

#include <algorithm>
#include <vector>

namespace arbor::bayestree {

template <class G>
class RelinearizationCheck {
 public:
  static constexpr int D = G::kDoF;
  static constexpr int kTrans = G::kDim;  // the first kDim tangent entries are translational
  using Vec = typename G::Tangent;

  /// A new pose (no candidate).
  void addPose() { is_candidate_.push_back(0); }
  /// Variable v was solved: a candidate of the next check.
  void solved(int v) {
    if (is_candidate_[v]) return;
    is_candidate_[v] = 1;
    candidates_.push_back(v);
  }
  /// Δ was set outside the solve: the next check scans every variable.
  void scanAll() { all_ = true; }
  /// The candidates are consumed unchecked (every variable is relinearised, or Δ is replaced).
  void consume() {
    for (int v : candidates_) is_candidate_[v] = 0;
    candidates_.clear();
    all_ = false;
  }
  /// Whether Δ_v crosses β.
  static bool exceeds(const Vec& dx, double beta_translation, double beta_rotation) {
    return dx.template head<kTrans>().cwiseAbs().maxCoeff() > beta_translation ||
           dx.template tail<D - kTrans>().cwiseAbs().maxCoeff() > beta_rotation;
  }
  /// The check: appends to *marked (M) the variables not fixed, in the tree (clique_of ≥ 0),
  /// whose Δ crosses β, in increasing order, and consumes the candidates. Returns the number of
  /// variables checked.
  int mark(const std::vector<Vec>& delta, const std::vector<char>& fixed,
           const std::vector<int>& clique_of, double beta_translation, double beta_rotation,
           std::vector<int>* marked) {
    auto crossed = [&](int v) {
      return !fixed[v] && clique_of[v] >= 0 && exceeds(delta[v], beta_translation, beta_rotation);
    };
    int checked = 0;
    if (all_) {
      checked = static_cast<int>(delta.size());
      for (int v = 0; v < checked; ++v)
        if (crossed(v)) marked->push_back(v);
    } else {
      // The few that crossed sorted, not every candidate.
      const auto first = marked->size();
      for (int v : candidates_)
        if (crossed(v)) marked->push_back(v);
      std::sort(marked->begin() + static_cast<std::ptrdiff_t>(first), marked->end());
      checked = static_cast<int>(candidates_.size());
    }
    consume();
    return checked;
  }

 private:
  std::vector<int> candidates_;
  std::vector<char> is_candidate_;
  bool all_ = false;
};

}  // namespace arbor::bayestree
