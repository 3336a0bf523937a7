#include "arbor_slam/core/so3.h"

#include <cmath>

namespace arbor::so3 {

Eigen::Matrix3d hat(const Eigen::Vector3d& w) {
  Eigen::Matrix3d m;
  m << 0.0, -w.z(), w.y(),  //
      w.z(), 0.0, -w.x(),   //
      -w.y(), w.x(), 0.0;
  return m;
}

Eigen::Quaterniond Exp(const Eigen::Vector3d& w, Eigen::Matrix3d* J_r) {
  const double theta2 = w.squaredNorm();
  const double theta = std::sqrt(theta2);
  Eigen::Quaterniond q;
  if (theta < 1e-8) {
    q = Eigen::Quaterniond(1.0, 0.5 * w.x(), 0.5 * w.y(), 0.5 * w.z());
    q.normalize();
  } else {
    const double half = 0.5 * theta;
    const Eigen::Vector3d v = (std::sin(half) / theta) * w;
    q = Eigen::Quaterniond(std::cos(half), v.x(), v.y(), v.z());
  }
  if (J_r) *J_r = rightJacobian(w);
  return q;
}

Eigen::Vector3d Log(const Eigen::Quaterniond& q_in, Eigen::Matrix3d* J_r_inv) {
  const Eigen::Quaterniond q = canonical(q_in);
  const Eigen::Vector3d v = q.vec();
  const double s = v.norm();
  Eigen::Vector3d w;
  if (s < 1e-8) {
    // θ ≈ 2 s, so ω ≈ 2 v / w (first order, exact to O(s³)).
    w = (2.0 / q.w()) * v;
  } else {
    const double theta = 2.0 * std::atan2(s, q.w());
    w = (theta / s) * v;
  }
  if (J_r_inv) *J_r_inv = rightJacobianInverse(w);
  return w;
}

Eigen::Matrix3d rightJacobian(const Eigen::Vector3d& w) {
  const double theta2 = w.squaredNorm();
  const Eigen::Matrix3d W = hat(w);
  if (theta2 < 1e-10) return Eigen::Matrix3d::Identity() - 0.5 * W + (1.0 / 6.0) * W * W;
  const double theta = std::sqrt(theta2);
  return Eigen::Matrix3d::Identity() - ((1.0 - std::cos(theta)) / theta2) * W +
         ((theta - std::sin(theta)) / (theta2 * theta)) * W * W;
}

Eigen::Matrix3d rightJacobianInverse(const Eigen::Vector3d& w) {
  const double theta2 = w.squaredNorm();
  const Eigen::Matrix3d W = hat(w);
  if (theta2 < 1e-10) return Eigen::Matrix3d::Identity() + 0.5 * W + (1.0 / 12.0) * W * W;
  const double theta = std::sqrt(theta2);
  const double coeff = 1.0 / theta2 - (1.0 + std::cos(theta)) / (2.0 * theta * std::sin(theta));
  return Eigen::Matrix3d::Identity() + 0.5 * W + coeff * W * W;
}

Eigen::Quaterniond canonical(const Eigen::Quaterniond& q) {
  if (q.w() < 0.0) return Eigen::Quaterniond(-q.w(), -q.x(), -q.y(), -q.z());
  return q;
}

}  // namespace arbor::so3
