// arbor_slam.CustomFactor2 / CustomFactor3 (docs/python.md, "Factors of your own"): a factor of
// your own whose error, and optionally its Jacobians, are Python functions. PyFactorModel is the
// FactorModel<G> (core/factor_model.h) that calls them; CustomFactorObject is what the Python
// object holds (the keys as pose ids, the model, Ω), handed to Graph.add_factor and
// OnlineSmoother.add_factor.
#pragma once

#include <memory>
#include <string>
#include <vector>

#include <pybind11/pybind11.h>
#include <Eigen/Core>

#include "arbor_slam/core/custom_factor.h"
#include "arbor_slam/core/factor_error.h"
#include "arbor_slam/core/factor_model.h"
#include "arbor_slam/core/pose_graph.h"

namespace arbor::python {

/// A FactorModel<G> whose evaluate() calls Python: error(*poses) → `rows` numbers and, when given,
/// jacobian(*poses) → arity rows×kDoF matrices (right perturbations, tangent [translation;
/// rotation]); without it, central differences through the retraction x ⊞ τ with step `step`
/// (2·arity·kDoF more calls of error). Thread-safe: every call takes the GIL (the smoother
/// linearises on worker threads while the update has released it). A Python exception in either
/// function propagates as pybind11::error_already_set, which the module turns back into the same
/// Python exception where the solve or update returns.
template <class G>
class PyFactorModel final : public FactorModel<G> {
 public:
  using typename FactorModel<G>::Residual;
  using typename FactorModel<G>::Jacobians;

  PyFactorModel(pybind11::object error, pybind11::object jacobian, int rows, int arity,
                std::string name, double step);
  ~PyFactorModel() override;
  PyFactorModel(const PyFactorModel&) = delete;
  PyFactorModel& operator=(const PyFactorModel&) = delete;

  int rows() const override { return rows_; }
  int arity() const override { return arity_; }
  std::string name() const override { return name_; }
  void evaluate(const std::array<const G*, 2>& x, Residual* e, Jacobians* J) const override;

  bool hasJacobian() const { return !jacobian_.is_none(); }
  double step() const { return step_; }

 private:
  Residual callError(const pybind11::tuple& poses) const;

  pybind11::object error_, jacobian_;
  int rows_, arity_;
  std::string name_;
  double step_;
};

/// For the module's exception translator: raises the Python exception at the bottom of a
/// FactorError (a factor's own function raised it: pybind11::error_already_set, or a
/// pybind11 builtin exception such as TypeError) with a note (PEP 678) naming the factor, and
/// returns true; false when the cause is not a Python one.
bool raiseCause(const FactorError& error);

template <class G>
struct CustomFactorObject {
  std::vector<Key> keys;  ///< one or two pose ids
  std::shared_ptr<const PyFactorModel<G>> model;
  Eigen::MatrixXd information;

  /// The library's factor on dense indices i (and j for a binary one), validated by
  /// CustomFactor::make (std::invalid_argument naming the problem).
  CustomFactor<G> make(int i, int j = -1) const {
    return CustomFactor<G>::make(model, information, i, j);
  }
};

}  // namespace arbor::python
