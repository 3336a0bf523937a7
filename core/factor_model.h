// The interface of a factor of your own on one or two poses (docs/design.md, "Factors of your
// own"): its error e(x₀[, x₁]) with rows() ≤ kDoF entries and the Jacobians
//
//   J_k = ∂e(…, x_k ⊞ τ_k, …)/∂τ_k at τ_k = 0,   x ⊞ τ = x·(Exp(ω), v),  τ = [v; ω],
//
// the right perturbations every built-in factor uses (docs/design.md, "Conventions"). Write one
// by deriving from UnaryFactorModel or BinaryFactorModel (analytic Jacobians), or let
// AutoDiffFactor (core/autodiff_factor.h) differentiate one error function templated on the
// scalar. CustomFactor (core/custom_factor.h) holds a model with its keys and Ω.
#pragma once

#include <array>
#include <string>

#include <Eigen/Core>

namespace arbor {

/// What a factor of your own computes. Implementations must be thread-safe for concurrent
/// const calls (the smoother linearises factors on two threads).
template <class G>
class FactorModel {
 public:
  static constexpr int kDoF = G::kDoF;
  using Residual = Eigen::Matrix<double, Eigen::Dynamic, 1, 0, kDoF, 1>;
  using Jacobian = Eigen::Matrix<double, Eigen::Dynamic, kDoF, 0, kDoF, kDoF>;
  using Jacobians = std::array<Jacobian, 2>;

  virtual ~FactorModel() = default;
  /// The residual dimension, 1..kDoF.
  virtual int rows() const = 0;
  /// The number of poses, 1 or 2.
  virtual int arity() const = 0;
  /// A name for messages ("range", "planar_motion", ...).
  virtual std::string name() const = 0;
  /// e at x[0..arity()) (rows() entries) and, when J is not null, (*J)[k] = ∂e/∂τ_k
  /// (rows()×kDoF) for k < arity().
  virtual void evaluate(const std::array<const G*, 2>& x, Residual* e, Jacobians* J) const = 0;
};

/// An analytic unary factor: implement error(x, J) with J = ∂e/∂τ (kRows×kDoF) when not null.
template <class G, int kRows>
class UnaryFactorModel : public FactorModel<G> {
 public:
  static_assert(kRows >= 1 && kRows <= G::kDoF, "a residual has 1..kDoF rows");
  using Error = Eigen::Matrix<double, kRows, 1>;
  using Jacobian = Eigen::Matrix<double, kRows, G::kDoF>;

  virtual Error error(const G& x, Jacobian* J) const = 0;

  int rows() const final { return kRows; }
  int arity() const final { return 1; }
  void evaluate(const std::array<const G*, 2>& x, typename FactorModel<G>::Residual* e,
                typename FactorModel<G>::Jacobians* J) const final {
    Jacobian J0;
    *e = error(*x[0], J ? &J0 : nullptr);
    if (J) (*J)[0] = J0;
  }
};

/// An analytic binary factor: implement error(xi, xj, Ji, Jj) with Ji = ∂e/∂τᵢ, Jj = ∂e/∂τⱼ
/// (kRows×kDoF) when not null.
template <class G, int kRows>
class BinaryFactorModel : public FactorModel<G> {
 public:
  static_assert(kRows >= 1 && kRows <= G::kDoF, "a residual has 1..kDoF rows");
  using Error = Eigen::Matrix<double, kRows, 1>;
  using Jacobian = Eigen::Matrix<double, kRows, G::kDoF>;

  virtual Error error(const G& xi, const G& xj, Jacobian* Ji, Jacobian* Jj) const = 0;

  int rows() const final { return kRows; }
  int arity() const final { return 2; }
  void evaluate(const std::array<const G*, 2>& x, typename FactorModel<G>::Residual* e,
                typename FactorModel<G>::Jacobians* J) const final {
    Jacobian Ji, Jj;
    *e = J ? error(*x[0], *x[1], &Ji, &Jj) : error(*x[0], *x[1], nullptr, nullptr);
    if (!J) return;
    (*J)[0] = Ji;
    (*J)[1] = Jj;
  }
};

}  // namespace arbor
