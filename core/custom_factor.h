// A factor of your own (core/factor_model.h) with its keys and information Ω (rows()×rows()):
// cost eᵀΩe and, as every built-in factor, the whitened linearisation
//
//   Ω = L Lᵀ,  r = Lᵀ e,  A_k = Lᵀ J_k,   ‖Σ_k A_k τ_k + r‖²,
//
// zero-padded to kDoF rows (zero rows change neither AᵀA nor Aᵀr; docs/design.md, "Factors").
// Factor<G> (core/factor.h) holds one as its custom alternative, so the smoother, the batch
// solvers, the robust kernels and the covariances take it without an edit of theirs.
#pragma once

#include <array>
#include <memory>
#include <stdexcept>
#include <string>
#include <utility>

#include <Eigen/Cholesky>
#include <Eigen/Core>

#include "arbor_slam/core/factor_model.h"
#include "arbor_slam/core/information.h"

namespace arbor {

template <class G>
struct CustomFactor {
  static constexpr int kDoF = G::kDoF;
  using Model = FactorModel<G>;
  using Matrix = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, 0, kDoF, kDoF>;
  using Block = Eigen::Matrix<double, kDoF, kDoF>;
  using Vector = Eigen::Matrix<double, kDoF, 1>;
  using Residual = typename Model::Residual;

  int i = 0;   ///< the first pose (dense index)
  int j = -1;  ///< the second pose of a binary factor, −1 for a unary one
  std::shared_ptr<const Model> model;
  Matrix information;
  Matrix sqrt_information_t;  ///< Lᵀ with Ω = L Lᵀ

  /// Validates the model, the keys and Ω (throws std::invalid_argument naming the problem) and
  /// factors Ω. Keys are dense pose indices: i for a unary model, i and j ≠ i for a binary one.
  static CustomFactor make(std::shared_ptr<const Model> model, const Eigen::MatrixXd& omega, int i,
                           int j = -1) {
    if (!model) throw std::invalid_argument("custom factor: no model");
    const std::string where = "custom factor '" + model->name() + "': ";
    const int rows = model->rows(), arity = model->arity();
    if (rows < 1 || rows > kDoF)
      throw std::invalid_argument(where + "residual of " + std::to_string(rows) +
                                  " rows, outside 1.." + std::to_string(kDoF));
    if (arity != 1 && arity != 2)
      throw std::invalid_argument(where + "arity " + std::to_string(arity) + ", not 1 or 2");
    if (i < 0) throw std::invalid_argument(where + "pose index " + std::to_string(i));
    if (arity == 2 && (j < 0 || j == i))
      throw std::invalid_argument(where + "second pose index " + std::to_string(j) +
                                  (j == i ? " equals the first" : ""));
    if (arity == 1 && j != -1)
      throw std::invalid_argument(where + "unary, given a second pose index " + std::to_string(j));
    if (omega.rows() != rows || omega.cols() != rows)
      throw std::invalid_argument(where + "information matrix " + std::to_string(omega.rows()) +
                                  "x" + std::to_string(omega.cols()) + " for a residual of " +
                                  std::to_string(rows) + " rows");
    const std::string problem = informationProblem(omega);
    if (!problem.empty()) throw std::invalid_argument(where + "information matrix " + problem);
    CustomFactor f;
    f.i = i;
    f.j = arity == 2 ? j : -1;
    f.model = std::move(model);
    f.information = 0.5 * (omega + omega.transpose());
    f.sqrt_information_t = Eigen::LLT<Eigen::MatrixXd>(f.information).matrixU();
    return f;
  }

  /// "(1, nan, 2)": a residual's or a Jacobian's entries (column by column) for messages.
  template <class M>
  static std::string valuesText(const M& m) {
    std::string s = "(";
    for (Eigen::Index k = 0; k < m.size(); ++k) s += (k ? ", " : "") + std::to_string(m.data()[k]);
    return s + ")";
  }

  int arity() const { return j < 0 ? 1 : 2; }
  int rows() const { return static_cast<int>(information.rows()); }
  std::string name() const { return model ? model->name() : "custom"; }

  /// e at the poses x (indexed by key) with optional Jacobians.
  template <class Poses>
  Residual error(const Poses& x, typename Model::Jacobians* J = nullptr) const {
    const std::array<const G*, 2> at{&x[i], j < 0 ? nullptr : &x[j]};
    Residual e;
    model->evaluate(at, &e, J);
    if (e.size() != rows())
      throw std::invalid_argument("custom factor '" + name() + "': error of " +
                                  std::to_string(e.size()) + " entries, expected " +
                                  std::to_string(rows()));
    if (!e.allFinite())
      throw std::invalid_argument("custom factor '" + name() +
                                  "': error not finite: " + valuesText(e));
    return e;
  }
  template <class Poses>
  double cost(const Poses& x) const {
    const Residual e = error(x);
    return e.dot(information * e);
  }
  /// Whitened linearisation, zero-padded to kDoF rows: A[k] = Lᵀ J_k, r = Lᵀ e.
  template <class Poses>
  void linearize(const Poses& x, Block* A0, Block* A1, Vector* r) const {
    typename Model::Jacobians J;
    const Residual e = error(x, &J);
    const int m = rows();
    Block* A[2] = {A0, A1};
    for (int k = 0; k < arity(); ++k) {
      const auto& Jk = J[static_cast<size_t>(k)];
      if (Jk.rows() != m)
        throw std::invalid_argument("custom factor '" + name() + "': Jacobian of " +
                                    std::to_string(Jk.rows()) + " rows, expected " +
                                    std::to_string(m));
      if (!Jk.allFinite())
        throw std::invalid_argument("custom factor '" + name() + "': Jacobian " +
                                    std::to_string(k) + " not finite: " + valuesText(Jk));
      A[k]->setZero();
      A[k]->topRows(m).noalias() = sqrt_information_t * Jk;
    }
    r->setZero();
    r->head(m).noalias() = sqrt_information_t * e;
  }
};

}  // namespace arbor
