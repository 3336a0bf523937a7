#include "arbor_slam/core/se3.h"

#include <cmath>

#include <Eigen/LU>

#include "arbor_slam/core/so3.h"

namespace arbor {
namespace {

// The off-diagonal block Q(ρ, θ) of the left Jacobian of SE(3) (Barfoot; Solà eq. 180).
Eigen::Matrix3d leftJacobianQ(const Eigen::Vector3d& rho, const Eigen::Vector3d& theta_vec) {
  const Eigen::Matrix3d P = so3::hat(rho);
  const Eigen::Matrix3d T = so3::hat(theta_vec);
  const double t2 = theta_vec.squaredNorm();
  double a, b, c;
  if (t2 < 1e-8) {
    a = 1.0 / 6.0 - t2 / 120.0;
    b = -1.0 / 24.0 + t2 / 720.0;
    c = 1.0 / 120.0;
  } else {
    const double t = std::sqrt(t2);
    const double s = std::sin(t), co = std::cos(t);
    a = (t - s) / (t2 * t);
    b = (1.0 - t2 / 2.0 - co) / (t2 * t2);
    c = -0.5 * (b - 3.0 * (t - s - t2 * t / 6.0) / (t2 * t2 * t));
  }
  return 0.5 * P + a * (T * P + P * T + T * P * T) - b * (T * T * P + P * T * T - 3.0 * T * P * T) +
         c * (T * P * T * T + T * T * P * T);
}

}  // namespace

SE3::SE3(const Eigen::Quaterniond& q, const Eigen::Vector3d& t) : q_(q.normalized()), t_(t) {}

SE3 SE3::compose(const SE3& other, Jacobian* J_this, Jacobian* J_other) const {
  if (J_this) *J_this = other.inverse().Adj();
  if (J_other) J_other->setIdentity();
  SE3 r;
  r.q_ = q_ * other.q_;
  r.t_ = t_ + q_ * other.t_;
  return r;
}

SE3 SE3::inverse(Jacobian* J) const {
  if (J) *J = -Adj();
  SE3 r;
  r.q_ = q_.conjugate();
  r.t_ = -(r.q_ * t_);
  return r;
}

SE3 SE3::between(const SE3& other, Jacobian* J_this, Jacobian* J_other) const {
  const SE3 result = inverse().compose(other);
  if (J_this) *J_this = -result.inverse().Adj();
  if (J_other) J_other->setIdentity();
  return result;
}

SE3 SE3::Exp(const Tangent& tau, Jacobian* J_r) {
  const Eigen::Vector3d rho = tau.head<3>();
  const Eigen::Vector3d theta = tau.tail<3>();
  SE3 r;
  r.q_ = so3::Exp(theta);
  // V = Jl(θ) = Jr(−θ).
  r.t_ = so3::rightJacobian(-theta) * rho;
  if (J_r) *J_r = rightJacobian(tau);
  return r;
}

SE3::Tangent SE3::Log(Jacobian* J_r_inv) const {
  Tangent tau;
  const Eigen::Vector3d theta = so3::Log(q_);
  tau.tail<3>() = theta;
  tau.head<3>() = so3::rightJacobian(-theta).inverse() * t_;
  if (J_r_inv) *J_r_inv = rightJacobian(tau).inverse();
  return tau;
}

SE3::Jacobian SE3::rightJacobian(const Tangent& tau) {
  // Jr(τ) = Jl(−τ) = [[Jl(−θ), Q(−ρ, −θ)], [0, Jl(−θ)]].
  const Eigen::Vector3d rho = tau.head<3>();
  const Eigen::Vector3d theta = tau.tail<3>();
  Jacobian J = Jacobian::Zero();
  const Eigen::Matrix3d Jr = so3::rightJacobian(theta);
  J.topLeftCorner<3, 3>() = Jr;
  J.bottomRightCorner<3, 3>() = Jr;
  J.topRightCorner<3, 3>() = leftJacobianQ(-rho, -theta);
  return J;
}

SE3::Jacobian SE3::Adj() const {
  Jacobian A = Jacobian::Zero();
  const Eigen::Matrix3d R = rotation();
  A.topLeftCorner<3, 3>() = R;
  A.bottomRightCorner<3, 3>() = R;
  A.topRightCorner<3, 3>() = so3::hat(t_) * R;
  return A;
}

SE3 SE3::retract(const Tangent& tau) const {
  SE3 r;
  r.q_ = (q_ * so3::Exp(tau.tail<3>())).normalized();
  r.t_ = t_ + q_ * tau.head<3>();
  return r;
}

SE3::Tangent SE3::localCoordinates(const SE3& other) const {
  Tangent tau;
  tau.head<3>() = q_.conjugate() * (other.t_ - t_);
  tau.tail<3>() = so3::Log(q_.conjugate() * other.q_);
  return tau;
}

}  // namespace arbor
