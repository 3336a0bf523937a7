#include "arbor_slam/core/se2.h"

#include <cmath>

#include <Eigen/LU>

namespace arbor {

double wrapAngle(double theta) {
  double a = std::remainder(theta, 2.0 * M_PI);  // in [−π, π]
  if (a <= -M_PI) a += 2.0 * M_PI;
  return a;
}

SE2::SE2(double x, double y, double theta) : t_(x, y), c_(std::cos(theta)), s_(std::sin(theta)) {}

SE2::SE2(const Eigen::Vector2d& t, double theta)
    : t_(t), c_(std::cos(theta)), s_(std::sin(theta)) {}

double SE2::angle() const { return std::atan2(s_, c_); }

Eigen::Matrix2d SE2::rotation() const {
  Eigen::Matrix2d R;
  R << c_, -s_, s_, c_;
  return R;
}

SE2 SE2::compose(const SE2& other, Jacobian* J_this, Jacobian* J_other) const {
  if (J_this) *J_this = other.inverse().Adj();
  if (J_other) J_other->setIdentity();
  return SE2(t_ + rotation() * other.t_, c_ * other.c_ - s_ * other.s_,
             s_ * other.c_ + c_ * other.s_);
}

SE2 SE2::inverse(Jacobian* J) const {
  if (J) *J = -Adj();
  return SE2(-rotation().transpose() * t_, c_, -s_);
}

SE2 SE2::between(const SE2& other, Jacobian* J_this, Jacobian* J_other) const {
  const SE2 result = inverse().compose(other);
  if (J_this) *J_this = -result.inverse().Adj();
  if (J_other) J_other->setIdentity();
  return result;
}

SE2 SE2::Exp(const Tangent& tau, Jacobian* J_r) {
  const double theta = tau(2);
  const double c = std::cos(theta);
  const double s = std::sin(theta);
  double A, B;  // sin θ/θ and (1 − cos θ)/θ
  if (std::abs(theta) < 1e-8) {
    A = 1.0 - theta * theta / 6.0;
    B = 0.5 * theta;
  } else {
    A = s / theta;
    B = (1.0 - c) / theta;
  }
  const Eigen::Vector2d t(A * tau(0) - B * tau(1), B * tau(0) + A * tau(1));
  if (J_r) {
    // Solà et al. (2018), eq. (163).
    Jacobian& J = *J_r;
    J.setIdentity();
    J(0, 0) = A;
    J(0, 1) = B;
    J(1, 0) = -B;
    J(1, 1) = A;
    if (std::abs(theta) < 1e-8) {
      J(0, 2) = -tau(1) / 2.0 + theta * tau(0) / 6.0;
      J(1, 2) = tau(0) / 2.0 + theta * tau(1) / 6.0;
    } else {
      const double t2 = theta * theta;
      J(0, 2) = (theta * tau(0) - tau(1) + tau(1) * c - tau(0) * s) / t2;
      J(1, 2) = (tau(0) + theta * tau(1) - tau(0) * c - tau(1) * s) / t2;
    }
  }
  return SE2(t, c, s);
}

SE2::Tangent SE2::Log(Jacobian* J_r_inv) const {
  const double theta = angle();
  double A, B;
  if (std::abs(theta) < 1e-8) {
    A = 1.0 - theta * theta / 6.0;
    B = 0.5 * theta;
  } else {
    A = s_ / theta;
    B = (1.0 - c_) / theta;
  }
  // V⁻¹ t with V = [[A, −B], [B, A]].
  const double det = A * A + B * B;
  Tangent tau;
  tau << (A * t_.x() + B * t_.y()) / det, (-B * t_.x() + A * t_.y()) / det, theta;
  if (J_r_inv) {
    Jacobian J;
    Exp(tau, &J);
    *J_r_inv = J.inverse();
  }
  return tau;
}

SE2::Jacobian SE2::Adj() const {
  Jacobian A = Jacobian::Identity();
  A.topLeftCorner<2, 2>() = rotation();
  A(0, 2) = t_.y();
  A(1, 2) = -t_.x();
  return A;
}

SE2 SE2::retract(const Tangent& tau) const {
  const double c = std::cos(tau(2));
  const double s = std::sin(tau(2));
  return SE2(t_ + rotation() * tau.head<2>(), c_ * c - s_ * s, s_ * c + c_ * s);
}

SE2::Tangent SE2::localCoordinates(const SE2& other) const {
  Tangent tau;
  tau.head<2>() = rotation().transpose() * (other.t_ - t_);
  tau(2) = std::atan2(c_ * other.s_ - s_ * other.c_, c_ * other.c_ + s_ * other.s_);
  return tau;
}

void SE2::normalize() {
  const double n = std::hypot(c_, s_);
  c_ /= n;
  s_ /= n;
}

}  // namespace arbor
