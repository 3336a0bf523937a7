// One factor of the smoother's objective: a relative pose (binary), a pose prior or a position
// prior (unary), or a factor of your own on one or two poses (core/custom_factor.h), as a value
// type with static dispatch (std::variant) so that the built-ins' dense kernels stay inlined. Every
// factor linearises into whitened blocks of one common shape,
//
//   ‖Σ_k A_k τ_{key k} + r‖²,   A_k: kDoF×kDoF,  r: kDoF,
//
// where a factor whose residual has fewer than kDoF entries (the position prior: kDim) fills the
// remaining rows with zeros; zero rows change neither AᵀA nor Aᵀr, so the Bayes tree can treat
// every factor alike (docs/design.md, "Factors"; your own: "Factors of your own").
//
// A factor may carry a robust kernel (core/robust_kernel.h; default none) and an inlier weight
// w ∈ [0, 1] (default 1) that an iteratively reweighted solver sets from the kernel, w = ρ′(s)
// at s = eᵀΩe: linearizeWeighted() scales the whitened A and r by √w, so ‖√w (A τ + r)‖² =
// w‖A τ + r‖² is the IRLS model (docs/design.md, "Robust kernels and GNC"). cost() stays the
// plain eᵀΩe (the clean objective every report uses); robustCost() is ρ(eᵀΩe).
#pragma once

#include <array>
#include <cmath>
#include <string>
#include <type_traits>
#include <variant>
#include <vector>

#include <Eigen/Core>

#include "arbor_slam/core/custom_factor.h"
#include "arbor_slam/core/pose_graph.h"
#include "arbor_slam/core/prior_factors.h"
#include "arbor_slam/core/relative_pose_factor.h"
#include "arbor_slam/core/robust_kernel.h"

namespace arbor {

enum class FactorKind { kRelativePose, kPosePrior, kPositionPrior, kCustom };

/// "relative_pose", "pose_prior", "position_prior", "custom"
const char* toString(FactorKind kind);

template <class G>
class Factor {
 public:
  static constexpr int kDoF = G::kDoF;
  static constexpr int kMaxKeys = 2;
  using Block = Eigen::Matrix<double, kDoF, kDoF>;
  using Vector = Eigen::Matrix<double, kDoF, 1>;
  using Variant = std::variant<RelativePoseEdge<G>, PosePriorFactor<G>, PositionPriorFactor<G>,
                               CustomFactor<G>>;

  /// The whitened linearisation ‖Σ_k A[k] τ_k + r‖² over the factor's keys (arity() of them).
  struct Linearization {
    std::array<Block, kMaxKeys> A;
    Vector r;
  };

  Factor() = default;
  Factor(const RelativePoseEdge<G>& f) : f_(f) {}     // NOLINT: implicit on purpose
  Factor(const PosePriorFactor<G>& f) : f_(f) {}      // NOLINT
  Factor(const PositionPriorFactor<G>& f) : f_(f) {}  // NOLINT
  Factor(const CustomFactor<G>& f) : f_(f) {}         // NOLINT

  FactorKind kind() const { return static_cast<FactorKind>(f_.index()); }
  int arity() const {
    if (const auto* c = std::get_if<CustomFactor<G>>(&f_)) return c->arity();
    return kind() == FactorKind::kRelativePose ? 2 : 1;
  }
  /// The k-th key (dense pose index): i then j for a binary factor.
  int key(int k) const {
    if (const auto* e = std::get_if<RelativePoseEdge<G>>(&f_)) return k == 0 ? e->i : e->j;
    if (const auto* c = std::get_if<CustomFactor<G>>(&f_)) return k == 0 ? c->i : c->j;
    return std::visit([](const auto& f) { return f.i; }, f_);
  }
  /// Renumbers the keys (k-th key → keys[k]).
  void setKeys(int k0, int k1 = -1) {
    if (auto* e = std::get_if<RelativePoseEdge<G>>(&f_)) {
      e->i = k0;
      e->j = k1;
      return;
    }
    if (auto* c = std::get_if<CustomFactor<G>>(&f_)) {
      c->i = k0;
      if (c->arity() == 2) c->j = k1;
      return;
    }
    std::visit([&](auto& f) { f.i = k0; }, f_);
  }
  bool involves(int v) const { return key(0) == v || (arity() > 1 && key(1) == v); }

  const Variant& variant() const { return f_; }
  const RelativePoseEdge<G>* relativePose() const { return std::get_if<RelativePoseEdge<G>>(&f_); }
  const PosePriorFactor<G>* posePrior() const { return std::get_if<PosePriorFactor<G>>(&f_); }
  const PositionPriorFactor<G>* positionPrior() const {
    return std::get_if<PositionPriorFactor<G>>(&f_);
  }
  const CustomFactor<G>* custom() const { return std::get_if<CustomFactor<G>>(&f_); }
  /// "relative_pose", "pose_prior", "position_prior", or a custom factor's model name.
  std::string name() const { return custom() ? custom()->name() : toString(kind()); }

  /// eᵀΩe at the poses x (indexed by key).
  template <class Poses>
  double cost(const Poses& x) const {
    return std::visit(
        [&](const auto& f) {
          using F = std::decay_t<decltype(f)>;
          if constexpr (std::is_same_v<F, RelativePoseEdge<G>>)
            return f.cost(x[f.i], x[f.j]);
          else if constexpr (std::is_same_v<F, CustomFactor<G>>)
            return f.cost(x);
          else
            return f.cost(x[f.i]);
        },
        f_);
  }

  /// The kernel on eᵀΩe (none by default) and the inlier weight the solvers use (1 by default).
  const RobustKernel& kernel() const { return kernel_; }
  void setKernel(const RobustKernel& kernel) { kernel_ = kernel; }
  double inlierWeight() const { return inlier_weight_; }
  void setInlierWeight(double w) { inlier_weight_ = w; }

  /// ρ(eᵀΩe) at the poses x: the kernel's cost (= cost() without a kernel).
  template <class Poses>
  double robustCost(const Poses& x) const {
    return kernel_.rho(cost(x));
  }
  /// w = ρ′(eᵀΩe) at the poses x: the IRLS weight the kernel gives there (1 without a kernel).
  template <class Poses>
  double kernelWeight(const Poses& x) const {
    return kernel_.isNone() ? 1.0 : kernel_.weight(cost(x));
  }

  /// The whitened linearisation scaled by √inlierWeight(): the IRLS model w‖Σ A τ + r‖².
  template <class Poses>
  void linearizeWeighted(const Poses& x, Linearization* out) const {
    linearize(x, out);
    if (inlier_weight_ == 1.0) return;
    const double root = std::sqrt(inlier_weight_);
    for (int k = 0; k < arity(); ++k) out->A[k] *= root;
    out->r *= root;
  }

  /// The whitened linearisation at the poses x (indexed by key).
  template <class Poses>
  void linearize(const Poses& x, Linearization* out) const {
    std::visit(
        [&](const auto& f) {
          using F = std::decay_t<decltype(f)>;
          if constexpr (std::is_same_v<F, RelativePoseEdge<G>>) {
            f.linearize(x[f.i], x[f.j], &out->A[0], &out->A[1], &out->r);
          } else if constexpr (std::is_same_v<F, CustomFactor<G>>) {
            f.linearize(x, &out->A[0], &out->A[1], &out->r);  // zero-padded there
          } else if constexpr (F::kRows == kDoF) {
            f.linearize(x[f.i], &out->A[0], &out->r);
          } else {  // fewer residual rows: zero-padded
            typename F::Jacobian A;
            typename F::Vector r;
            f.linearize(x[f.i], &A, &r);
            out->A[0].setZero();
            out->A[0].template topRows<F::kRows>() = A;
            out->r.setZero();
            out->r.template head<F::kRows>() = r;
          }
        },
        f_);
  }

  /// Whether the measurement and information are finite and Ω's square root is (a factor built
  /// by make() always is; one assembled by hand may not be).
  bool isFinite() const;

 private:
  Variant f_;
  RobustKernel kernel_;
  double inlier_weight_ = 1.0;
};

/// Appends f to the graph's edges, pose priors, position priors or custom factors, by its kind.
template <class G>
void addToGraph(const Factor<G>& f, PoseGraph<G>* graph) {
  if (const auto* e = f.relativePose()) graph->edges.push_back(*e);
  if (const auto* p = f.posePrior()) graph->pose_priors.push_back(*p);
  if (const auto* p = f.positionPrior()) graph->position_priors.push_back(*p);
  if (const auto* c = f.custom()) graph->custom_factors.push_back(*c);
}

/// Every factor of the graph: its edges, then its pose priors, its position priors and its
/// custom factors.
template <class G>
std::vector<Factor<G>> factorsOf(const PoseGraph<G>& graph) {
  std::vector<Factor<G>> out;
  out.reserve(graph.edges.size() + graph.pose_priors.size() + graph.position_priors.size() +
              graph.custom_factors.size());
  for (const auto& e : graph.edges) out.emplace_back(e);
  for (const auto& p : graph.pose_priors) out.emplace_back(p);
  for (const auto& p : graph.position_priors) out.emplace_back(p);
  for (const auto& c : graph.custom_factors) out.emplace_back(c);
  return out;
}

extern template class Factor<SE2>;
extern template class Factor<SE3>;

using Factor2 = Factor<SE2>;
using Factor3 = Factor<SE3>;

}  // namespace arbor
