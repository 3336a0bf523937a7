// The relative-pose ("between") error term, in the Ceres/GTSAM convention:
//   δ = zᵢⱼ⁻¹ (xᵢ⁻¹ xⱼ),  e = [t(δ); wrap θ(δ)] (2D),  e = [t(δ); 2·vec q(δ), q_w ≥ 0] (3D),
// cost eᵀ Ω e. Jacobians are taken with respect to right perturbations xᵢ ⊞ τᵢ, xⱼ ⊞ τⱼ.
#pragma once

#include <sstream>
#include <stdexcept>
#include <string>

#include <Eigen/Cholesky>
#include <Eigen/Core>

#include "arbor_slam/core/information.h"
#include "arbor_slam/core/se2.h"
#include "arbor_slam/core/se3.h"

namespace arbor {

/// The largest |translation component| accepted in a measurement or a pose. Beyond it,
/// residuals weighted by Ω (entries up to kMaxInformationEntry) can overflow F = Σ eᵀΩe
/// (docs/design.md, "Conventions": input limits).
inline constexpr double kMaxTranslation = 1e15;

/// Why x cannot be a measurement or a pose, or "" when it can: a translation component beyond
/// kMaxTranslation in magnitude (finiteness is checked where values are parsed).
template <class Group>
std::string translationProblem(const Group& x) {
  const double largest = x.translation().cwiseAbs().maxCoeff();
  if (!(largest > kMaxTranslation)) return "";
  std::ostringstream os;
  os << "translation component of magnitude " << largest << " beyond the largest accepted ("
     << kMaxTranslation << ")";
  return os.str();
}

/// e(z, xᵢ, xⱼ) with optional ∂e/∂τᵢ and ∂e/∂τⱼ.
Eigen::Vector3d relativePoseError(const SE2& z, const SE2& xi, const SE2& xj,
                                  SE2::Jacobian* J_i = nullptr, SE2::Jacobian* J_j = nullptr);
Eigen::Matrix<double, 6, 1> relativePoseError(const SE3& z, const SE3& xi, const SE3& xj,
                                              SE3::Jacobian* J_i = nullptr,
                                              SE3::Jacobian* J_j = nullptr);

/// One measurement zᵢⱼ with information Ω between dense pose indices i and j.
/// Ω = L Lᵀ; the whitened residual is r = Lᵀ e, so ‖r‖² = eᵀ Ω e.
template <class Group>
struct RelativePoseEdge {
  static constexpr int kDoF = Group::kDoF;
  using Matrix = Eigen::Matrix<double, kDoF, kDoF>;
  using Vector = Eigen::Matrix<double, kDoF, 1>;

  int i = 0;
  int j = 0;
  Group measurement;
  Matrix information = Matrix::Identity();
  Matrix sqrt_information_t = Matrix::Identity();  ///< Lᵀ (upper triangular)

  /// Validates Ω (throws std::invalid_argument naming the problem) and factors it.
  static RelativePoseEdge make(int i, int j, const Group& z, const Matrix& omega) {
    const std::string problem = informationProblem(omega);
    if (!problem.empty()) throw std::invalid_argument("information matrix " + problem);
    const std::string far = translationProblem(z);
    if (!far.empty()) throw std::invalid_argument("measurement " + far);
    RelativePoseEdge e;
    e.i = i;
    e.j = j;
    e.measurement = z;
    e.information = 0.5 * (omega + omega.transpose());
    e.sqrt_information_t = Eigen::LLT<Matrix>(e.information).matrixU();
    return e;
  }

  Vector error(const Group& xi, const Group& xj) const {
    return relativePoseError(measurement, xi, xj);
  }
  double cost(const Group& xi, const Group& xj) const {
    const Vector e = error(xi, xj);
    return e.dot(information * e);
  }

  /// Whitened linearisation: r = Lᵀe, A_i = Lᵀ ∂e/∂τᵢ, A_j = Lᵀ ∂e/∂τⱼ.
  /// The linear model is ‖A_i τᵢ + A_j τⱼ + r‖².
  void linearize(const Group& xi, const Group& xj, Matrix* A_i, Matrix* A_j, Vector* r) const {
    typename Group::Jacobian Ji, Jj;
    const Vector e = relativePoseError(measurement, xi, xj, &Ji, &Jj);
    *A_i = sqrt_information_t * Ji;
    *A_j = sqrt_information_t * Jj;
    *r = sqrt_information_t * e;
  }
};

using Edge2 = RelativePoseEdge<SE2>;
using Edge3 = RelativePoseEdge<SE3>;

}  // namespace arbor
