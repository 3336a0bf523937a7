// Unary factors on one pose, in the world frame (docs/design.md, "Factors"):
//
//   pose prior      δ = z⁻¹ x o,  e = [t(δ); wrap θ(δ)] (2D), [t(δ); 2·vec q(δ)] (3D), cost eᵀΩe,
//                   with a sensor offset o (identity unless given: g2o's PARAMS_SE3OFFSET) —
//                   the relative-pose error of core/relative_pose_factor.h with xᵢ = I and
//                   xⱼ = x o (g2o's EDGE_PRIOR_SE2 / EDGE_SE3_PRIOR, GTSAM's PriorFactor<Pose>);
//   position prior  e = t(x) − p (kDim entries: a GPS fix in a local frame), cost eᵀΩe with Ω
//                   kDim×kDim (GTSAM's GPSFactor, g2o's EDGE_PRIOR_SE2_XY / EDGE_SE3_XYZ_PRIOR).
//
// Jacobians are taken with respect to the right perturbation x ⊞ τ = x·(Exp(ω), v), so
// t(x ⊞ τ) = t + R v and ∂e/∂τ = [R 0] for the position prior; for the pose prior
// x Exp(τ) o = x o Exp(Ad(o⁻¹) τ), so ∂e/∂τ = ∂e/∂τⱼ(x o) · Ad(o⁻¹).
#pragma once

#include <stdexcept>
#include <string>

#include <Eigen/Cholesky>
#include <Eigen/Core>

#include "arbor_slam/core/information.h"
#include "arbor_slam/core/relative_pose_factor.h"

namespace arbor {

/// A prior on the whole pose i: the measurement z of x_i with information Ω (kDoF×kDoF).
template <class Group>
struct PosePriorFactor {
  static constexpr int kDoF = Group::kDoF;
  static constexpr int kRows = kDoF;  ///< residual dimension
  using Matrix = Eigen::Matrix<double, kDoF, kDoF>;
  using Vector = Eigen::Matrix<double, kDoF, 1>;
  using Jacobian = Eigen::Matrix<double, kRows, kDoF>;

  int i = 0;
  Group measurement;
  Matrix information = Matrix::Identity();
  Matrix sqrt_information_t = Matrix::Identity();  ///< Lᵀ with Ω = L Lᵀ
  Group offset;                                    ///< o: the prior is on x o
  bool has_offset = false;                         ///< o ≠ I (skips two products when false)

  /// Validates Ω and z (throws std::invalid_argument naming the problem) and factors Ω.
  static PosePriorFactor make(int i, const Group& z, const Matrix& omega,
                              const Group& offset = Group::Identity()) {
    const std::string problem = informationProblem(omega);
    if (!problem.empty()) throw std::invalid_argument("information matrix " + problem);
    const std::string far = translationProblem(z);
    if (!far.empty()) throw std::invalid_argument("measurement " + far);
    PosePriorFactor f;
    f.i = i;
    f.measurement = z;
    f.information = 0.5 * (omega + omega.transpose());
    f.sqrt_information_t = Eigen::LLT<Matrix>(f.information).matrixU();
    f.offset = offset;
    f.has_offset = offset.localCoordinates(Group::Identity()).cwiseAbs().maxCoeff() > 0;
    return f;
  }

  /// e(x) with optional ∂e/∂τ.
  Vector error(const Group& x, Jacobian* J = nullptr) const {
    if (!has_offset) return relativePoseError(measurement, Group::Identity(), x, nullptr, J);
    const Vector e =
        relativePoseError(measurement, Group::Identity(), x.compose(offset), nullptr, J);
    if (J) *J = *J * offset.inverse().Adj();
    return e;
  }
  double cost(const Group& x) const {
    const Vector e = error(x);
    return e.dot(information * e);
  }
  /// Whitened linearisation: r = Lᵀe, A = Lᵀ ∂e/∂τ; the linear model is ‖A τ + r‖².
  void linearize(const Group& x, Jacobian* A, Vector* r) const {
    Jacobian J;
    const Vector e = error(x, &J);
    *A = sqrt_information_t * J;
    *r = sqrt_information_t * e;
  }
};

/// A prior on the position of pose i: p in the world frame with information Ω (kDim×kDim).
template <class Group>
struct PositionPriorFactor {
  static constexpr int kDoF = Group::kDoF;
  static constexpr int kRows = Group::kDim;  ///< residual dimension
  using Matrix = Eigen::Matrix<double, kRows, kRows>;
  using Vector = Eigen::Matrix<double, kRows, 1>;
  using Jacobian = Eigen::Matrix<double, kRows, kDoF>;
  using Translation = typename Group::Translation;

  int i = 0;
  Translation position = Translation::Zero();
  Matrix information = Matrix::Identity();
  Matrix sqrt_information_t = Matrix::Identity();  ///< Lᵀ with Ω = L Lᵀ

  /// Validates Ω and p (throws std::invalid_argument naming the problem) and factors Ω.
  static PositionPriorFactor make(int i, const Translation& p, const Matrix& omega) {
    const std::string problem = informationProblem(omega);
    if (!problem.empty()) throw std::invalid_argument("information matrix " + problem);
    if (!p.allFinite()) throw std::invalid_argument("position not finite");
    const double largest = p.cwiseAbs().maxCoeff();
    if (largest > kMaxTranslation)
      throw std::invalid_argument("position component of magnitude " + std::to_string(largest) +
                                  " beyond the largest accepted");
    PositionPriorFactor f;
    f.i = i;
    f.position = p;
    f.information = 0.5 * (omega + omega.transpose());
    f.sqrt_information_t = Eigen::LLT<Matrix>(f.information).matrixU();
    return f;
  }

  /// e(x) = t(x) − p with optional ∂e/∂τ = [R 0].
  Vector error(const Group& x, Jacobian* J = nullptr) const {
    if (J) {
      J->setZero();
      J->template leftCols<kRows>() = x.rotation();
    }
    return x.translation() - position;
  }
  double cost(const Group& x) const {
    const Vector e = error(x);
    return e.dot(information * e);
  }
  void linearize(const Group& x, Jacobian* A, Vector* r) const {
    Jacobian J;
    const Vector e = error(x, &J);
    *A = sqrt_information_t * J;
    *r = sqrt_information_t * e;
  }
};

using PosePrior2 = PosePriorFactor<SE2>;
using PosePrior3 = PosePriorFactor<SE3>;
using PositionPrior2 = PositionPriorFactor<SE2>;
using PositionPrior3 = PositionPriorFactor<SE3>;

}  // namespace arbor
