#include "arbor_slam/core/relative_pose_factor.h"

#include "arbor_slam/core/so3.h"

namespace arbor {

// With m = xᵢ⁻¹xⱼ and δ = z⁻¹m: perturbing xⱼ gives δ·Exp(τⱼ); perturbing xᵢ gives
// z⁻¹Exp(−τᵢ)m = δ·Exp(−Ad(m⁻¹)τᵢ). So with D = ∂e(δ·Exp(τ))/∂τ at 0:
//   ∂e/∂τⱼ = D,   ∂e/∂τᵢ = −D·Ad(m⁻¹).

Eigen::Vector3d relativePoseError(const SE2& z, const SE2& xi, const SE2& xj, SE2::Jacobian* J_i,
                                  SE2::Jacobian* J_j) {
  const SE2 m = xi.between(xj);
  const SE2 delta = z.between(m);
  Eigen::Vector3d e(delta.x(), delta.y(), delta.angle());
  if (J_i || J_j) {
    SE2::Jacobian D = SE2::Jacobian::Identity();
    D.topLeftCorner<2, 2>() = delta.rotation();
    if (J_j) *J_j = D;
    if (J_i) *J_i = -D * m.inverse().Adj();
  }
  return e;
}

Eigen::Matrix<double, 6, 1> relativePoseError(const SE3& z, const SE3& xi, const SE3& xj,
                                              SE3::Jacobian* J_i, SE3::Jacobian* J_j) {
  const SE3 m = xi.between(xj);
  const SE3 delta = z.between(m);
  const Eigen::Quaterniond q = so3::canonical(delta.quaternion());
  Eigen::Matrix<double, 6, 1> e;
  e.head<3>() = delta.translation();
  e.tail<3>() = 2.0 * q.vec();
  if (J_i || J_j) {
    // ∂(2·vec(q ⊗ Exp(ω)))/∂ω = q_w I + [vec q]×.
    SE3::Jacobian D = SE3::Jacobian::Zero();
    D.topLeftCorner<3, 3>() = q.toRotationMatrix();
    D.bottomRightCorner<3, 3>() = q.w() * Eigen::Matrix3d::Identity() + so3::hat(q.vec());
    if (J_j) *J_j = D;
    if (J_i) *J_i = -D * m.inverse().Adj();
  }
  return e;
}

}  // namespace arbor
