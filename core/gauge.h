// The gauge of a pose graph: relative-pose edges leave every connected component free to move
// rigidly; priors (core/prior_factors.h) can fix that freedom. A component whose priors do not
// fix it is anchored at one pose (its first) held fixed: the anchor node of Kim et al.,
// "Multiple Relative Pose Graphs for Robust Cooperative Mapping", ICRA 2010, in its limit of
// infinite strength (docs/design.md, "Gauge and components").
//
// Whether priors fix the gauge: a rigid move x ↦ T x of the component, T = Exp(ξ), ξ = [v; ω],
// changes a pose prior's residual in every direction, and a position prior's by
// ∂(t(Tx) − p)/∂ξ = [I  ∂(Rₒ p)/∂ω] at p: [I  (−p_y, p_x)ᵀ] in 2D, [I  −[p]×] in 3D. The priors
// fix the gauge when the gauge information G = Σ JᵀΩJ is positive definite; with position priors
// alone that is decided on the rotational Schur complement S = G_ωω − G_ωv G_vv⁻¹ G_vω, which
// does not depend on where the origin is (two distinct positions in 2D, three non-collinear
// ones in 3D). A custom factor (core/custom_factor.h) adds its JᵀΩJ with the Jacobian of its
// error under the move, Exp(ξ)·x = x·Exp(Ad(x⁻¹) ξ) for every pose x, so J = Σ_k J_k Ad(x_k⁻¹)
// at the poses given (zero for one that depends only on xᵢ⁻¹xⱼ): a range to a known anchor
// fixes position, not heading; its gauge is decided on the same G.
#pragma once

#include <algorithm>
#include <numeric>
#include <vector>

#include <Eigen/Cholesky>
#include <Eigen/Core>
#include <Eigen/Eigenvalues>

#include "arbor_slam/core/custom_factor.h"
#include "arbor_slam/core/prior_factors.h"
#include "arbor_slam/core/relative_pose_factor.h"

namespace arbor {

/// What the priors of one component say about its gauge; additive (components join by add()).
template <class G>
class GaugeInformation {
 public:
  static constexpr int kDoF = G::kDoF;
  static constexpr int kDim = G::kDim;
  using Matrix = Eigen::Matrix<double, kDoF, kDoF>;

  void addPosePrior() { ++pose_priors_; }
  void addPositionPrior(const typename G::Translation& p,
                        const Eigen::Matrix<double, kDim, kDim>& omega) {
    Eigen::Matrix<double, kDim, kDoF> J = Eigen::Matrix<double, kDim, kDoF>::Zero();
    J.template leftCols<kDim>().setIdentity();
    if constexpr (kDim == 2) {
      J(0, 2) = -p.y();
      J(1, 2) = p.x();
    } else {
      J.template rightCols<3>() << 0, p.z(), -p.y(), -p.z(), 0, p.x(), p.y(), -p.x(), 0;
    }
    G_ += J.transpose() * omega * J;
    ++position_priors_;
  }
  /// A custom factor at the poses x (indexed by key; its terms under a rigid move of both keys).
  template <class Poses>
  void addCustom(const CustomFactor<G>& f, const Poses& x) {
    typename FactorModel<G>::Jacobians J;
    f.error(x, &J);
    using Jacobian = Eigen::Matrix<double, Eigen::Dynamic, kDoF, 0, kDoF, kDoF>;
    Jacobian Jxi = J[0] * x[f.i].inverse().Adj();
    if (f.arity() == 2) {
      // Entries that cancel to rounding (a factor of xᵢ⁻¹xⱼ alone) are exactly zero.
      const Jacobian Jj = J[1] * x[f.j].inverse().Adj();
      const Jacobian size = Jxi.cwiseAbs() + Jj.cwiseAbs();
      Jxi += Jj;
      Jxi = (Jxi.cwiseAbs().array() <= 1e-9 * size.array()).select(0.0, Jxi);
    }
    if (Jxi.isZero(0.0)) return;
    G_ += Jxi.transpose() * f.information * Jxi;
    ++custom_;
  }
  void add(const GaugeInformation& other) {
    G_ += other.G_;
    pose_priors_ += other.pose_priors_;
    position_priors_ += other.position_priors_;
    custom_ += other.custom_;
  }
  /// Takes back what add(other) added (a factor taken out before it was used).
  void remove(const GaugeInformation& other) {
    G_ -= other.G_;
    pose_priors_ -= other.pose_priors_;
    position_priors_ -= other.position_priors_;
    custom_ -= other.custom_;
  }

  int priors() const { return pose_priors_ + position_priors_; }
  int customFactors() const { return custom_; }
  /// Whether the priors fix every rigid motion of the component.
  bool fixesGauge() const {
    if (pose_priors_ > 0) return true;
    if (position_priors_ == 0 && custom_ == 0) return false;
    constexpr int kRot = kDoF - kDim;
    const auto Gvv = G_.template topLeftCorner<kDim, kDim>();
    const auto Gvw = G_.template topRightCorner<kDim, kRot>();
    const auto Gww = G_.template bottomRightCorner<kRot, kRot>();
    const Eigen::LLT<Eigen::Matrix<double, kDim, kDim>> llt(Gvv);
    if (llt.info() != Eigen::Success) return false;
    const Eigen::Matrix<double, kRot, kRot> S = Gww - Gvw.transpose() * llt.solve(Gvw);
    const double scale = std::max(Gww.trace(), 1e-300);
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix<double, kRot, kRot>> eig(
        0.5 * (S + S.transpose()), Eigen::EigenvaluesOnly);
    return eig.eigenvalues()(0) > 1e-9 * scale;
  }

 private:
  Matrix G_ = Matrix::Zero();
  int pose_priors_ = 0, position_priors_ = 0, custom_ = 0;
};

/// One pose per connected component (poses linked by edges and binary custom factors) whose
/// priors and custom factors do not fix its gauge: its lowest dense index, ascending. Poses
/// without any factor are components of their own. Custom factors' gauge information is taken at
/// `poses` (one per pose; with fewer, custom factors join components and anchor none). O(n + m).
template <class G>
std::vector<int> anchorPoses(int num_poses, const std::vector<RelativePoseEdge<G>>& edges,
                             const std::vector<PosePriorFactor<G>>& pose_priors,
                             const std::vector<PositionPriorFactor<G>>& position_priors,
                             const std::vector<CustomFactor<G>>& custom = {},
                             const std::vector<G>& poses = {}) {
  std::vector<int> parent(static_cast<size_t>(num_poses));
  std::iota(parent.begin(), parent.end(), 0);
  auto root = [&](int v) {
    while (parent[v] != v) v = parent[v] = parent[parent[v]];
    return v;
  };
  for (const auto& e : edges) {
    const int a = root(e.i), b = root(e.j);
    if (a != b) parent[std::max(a, b)] = std::min(a, b);  // the root is the lowest index
  }
  for (const auto& c : custom) {
    if (c.arity() < 2) continue;
    const int a = root(c.i), b = root(c.j);
    if (a != b) parent[std::max(a, b)] = std::min(a, b);
  }
  std::vector<GaugeInformation<G>> gauge(static_cast<size_t>(num_poses));
  for (const auto& p : pose_priors) gauge[root(p.i)].addPosePrior();
  for (const auto& p : position_priors)
    gauge[root(p.i)].addPositionPrior(p.position, p.information);
  if (static_cast<int>(poses.size()) == num_poses)
    for (const auto& c : custom) gauge[root(c.i)].addCustom(c, poses);
  std::vector<int> anchors;
  for (int v = 0; v < num_poses; ++v)
    if (root(v) == v && !gauge[v].fixesGauge()) anchors.push_back(v);
  return anchors;
}

}  // namespace arbor
