// SE(3): rigid motions in space, after Solà et al., "A micro Lie theory" (2018), §B and App. D.
// Tangent τ = [ρ; θ] (translational part first, as in the error e = [t; 2·vec q]).
// All Jacobians are right Jacobians (perturbations x ⊕ τ = x·Exp(τ)).
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>

namespace arbor {

class SE3 {
 public:
  static constexpr int kDoF = 6;
  static constexpr int kDim = 3;
  using Tangent = Eigen::Matrix<double, 6, 1>;
  using Jacobian = Eigen::Matrix<double, 6, 6>;
  using Translation = Eigen::Vector3d;
  using RotationMatrix = Eigen::Matrix3d;

  SE3() = default;
  SE3(const Eigen::Quaterniond& q, const Eigen::Vector3d& t);

  static SE3 Identity() { return SE3(); }

  const Eigen::Vector3d& translation() const { return t_; }
  const Eigen::Quaterniond& quaternion() const { return q_; }
  Eigen::Matrix3d rotation() const { return q_.toRotationMatrix(); }

  SE3 compose(const SE3& other, Jacobian* J_this = nullptr, Jacobian* J_other = nullptr) const;
  SE3 inverse(Jacobian* J = nullptr) const;
  SE3 between(const SE3& other, Jacobian* J_this = nullptr, Jacobian* J_other = nullptr) const;

  static SE3 Exp(const Tangent& tau, Jacobian* J_r = nullptr);
  Tangent Log(Jacobian* J_r_inv = nullptr) const;

  /// Adjoint: x·Exp(τ) = Exp(Ad_x τ)·x.
  Jacobian Adj() const;

  /// The retraction used by the solvers: x ⊞ τ = (q ⊗ Exp(θ), t + R ρ), i.e. x·(Exp(θ), ρ).
  /// It agrees with x·Exp(τ) to first order, so right Jacobians apply to it unchanged.
  SE3 retract(const Tangent& tau) const;
  /// The inverse of retract.
  Tangent localCoordinates(const SE3& other) const;

  Eigen::Vector3d act(const Eigen::Vector3d& p) const { return q_ * p + t_; }

  void normalize() { q_.normalize(); }

  /// Right Jacobian of Exp at τ and its inverse.
  static Jacobian rightJacobian(const Tangent& tau);

 private:
  Eigen::Quaterniond q_ = Eigen::Quaterniond::Identity();
  Eigen::Vector3d t_ = Eigen::Vector3d::Zero();
};

}  // namespace arbor
