// SE(2): planar rigid motions, after Solà et al., "A micro Lie theory" (2018), §B and App. C.
// Tangent τ = [v_x, v_y, θ]. All Jacobians are right Jacobians (perturbations x ⊕ τ = x·Exp(τ)).
#pragma once

#include <Eigen/Core>

namespace arbor {

class SE2 {
 public:
  static constexpr int kDoF = 3;  ///< tangent dimension
  static constexpr int kDim = 2;  ///< dimension of the space it acts on
  using Tangent = Eigen::Matrix<double, 3, 1>;
  using Jacobian = Eigen::Matrix<double, 3, 3>;
  using Translation = Eigen::Vector2d;
  using RotationMatrix = Eigen::Matrix2d;

  SE2() = default;
  SE2(double x, double y, double theta);
  SE2(const Eigen::Vector2d& t, double theta);

  static SE2 Identity() { return SE2(); }

  const Eigen::Vector2d& translation() const { return t_; }
  double x() const { return t_.x(); }
  double y() const { return t_.y(); }
  double angle() const;  ///< in (−π, π]
  double cos() const { return c_; }
  double sin() const { return s_; }
  Eigen::Matrix2d rotation() const;

  /// this · other; J_this = ∂/∂this, J_other = ∂/∂other.
  SE2 compose(const SE2& other, Jacobian* J_this = nullptr, Jacobian* J_other = nullptr) const;
  /// this⁻¹; J = ∂(this⁻¹)/∂this.
  SE2 inverse(Jacobian* J = nullptr) const;
  /// this⁻¹ · other; J_this, J_other as in compose.
  SE2 between(const SE2& other, Jacobian* J_this = nullptr, Jacobian* J_other = nullptr) const;

  static SE2 Exp(const Tangent& tau, Jacobian* J_r = nullptr);
  Tangent Log(Jacobian* J_r_inv = nullptr) const;

  /// Adjoint: x·Exp(τ) = Exp(Ad_x τ)·x.
  Jacobian Adj() const;

  /// The retraction used by the solvers: x ⊞ τ = (t + R v, θ + ω), i.e. x·(Exp(ω), v).
  /// It agrees with x·Exp(τ) to first order, so right Jacobians apply to it unchanged.
  SE2 retract(const Tangent& tau) const;
  /// The inverse of retract: other = this.retract(this.localCoordinates(other)).
  Tangent localCoordinates(const SE2& other) const;

  Eigen::Vector2d act(const Eigen::Vector2d& p) const { return rotation() * p + t_; }

  /// Re-normalises the rotation (after many compositions).
  void normalize();

 private:
  SE2(const Eigen::Vector2d& t, double c, double s) : t_(t), c_(c), s_(s) {}
  Eigen::Vector2d t_ = Eigen::Vector2d::Zero();
  double c_ = 1.0;  // cos θ
  double s_ = 0.0;  // sin θ
};

/// Wraps an angle to (−π, π].
double wrapAngle(double theta);

}  // namespace arbor
