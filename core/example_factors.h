// Factors of your own, as examples to copy (docs/design.md, "Factors of your own"): each is
// the math in a comment, then an autodiff functor (core/autodiff_factor.h) and, for two of
// them, the same factor with analytic Jacobians (core/factor_model.h). Jacobians are for
// right perturbations x ⊞ τ = (R Exp(ω), t + R v), τ = [v; ω]; tests/custom_factor_test.cc
// checks every one against central differences and the two forms against each other.
#pragma once

#include <Eigen/Core>

#include "arbor_slam/core/autodiff_factor.h"
#include "arbor_slam/core/factor_model.h"
#include "arbor_slam/core/se2.h"
#include "arbor_slam/core/se3.h"

namespace arbor::examples {

// Range to a known anchor a (a UWB beacon), 1 row, unary, 2D or 3D:
//   e = ‖t(x) − a‖ − ρ,   ∂e/∂v = uᵀ R,  ∂e/∂ω = 0,  u = (t − a)/‖t − a‖.
template <int kDim>
struct RangeError {
  Eigen::Matrix<double, kDim, 1> anchor;
  double range = 0;

  template <class T>
  Eigen::Matrix<T, 1, 1> operator()(const RigidMotion<T, kDim>& x) const {
    return Eigen::Matrix<T, 1, 1>((x.t - anchor.template cast<T>()).norm() - T(range));
  }
};
template <class G>
using RangeFactor = AutoDiffFactor<G, RangeError<G::kDim>, 1>;

// Planar motion in 3D (a ground vehicle: z, roll and pitch near 0), 3 rows, unary:
//   e = [t_z; R₂₁; −R₂₀] = [z; cos β sin α; sin β] for roll α and pitch β (ZYX), ≈ [z; α; β];
// with u = R₂.ᵀ (R's last row) and R(I + [ω]×)'s last row uᵀ + (u × ω)ᵀ:
//   ∂e/∂v = [uᵀ; 0; 0],   ∂e/∂ω = [0; (u_z, 0, −u_x); (0, u_z, −u_y)].
struct PlanarMotionError {
  template <class T>
  Eigen::Matrix<T, 3, 1> operator()(const RigidMotion3<T>& x) const {
    return Eigen::Matrix<T, 3, 1>(x.t(2), x.R(2, 1), -x.R(2, 0));
  }
};
using PlanarMotionAutoDiff = AutoDiffFactor<SE3, PlanarMotionError, 3>;

class PlanarMotionFactor final : public UnaryFactorModel<SE3, 3> {
 public:
  Error error(const SE3& x, Jacobian* J) const override {
    const Eigen::Matrix3d R = x.rotation();
    const Eigen::Vector3d u = R.row(2).transpose();
    if (J) {
      J->setZero();
      J->block<1, 3>(0, 0) = u.transpose();
      J->block<1, 3>(1, 3) << u.z(), 0, -u.x();
      J->block<1, 3>(2, 3) << 0, u.z(), -u.y();
    }
    return Error(x.translation().z(), R(2, 1), -R(2, 0));
  }
  std::string name() const override { return "planar_motion"; }
};

// Position of pose j in pose i's frame (a landmark-free "relative position", e.g. from a
// ranging-and-bearing pair), kDim rows, binary:
//   e = Rᵢᵀ(tⱼ − tᵢ) − p,  q = Rᵢᵀ(tⱼ − tᵢ):
//   ∂e/∂vᵢ = −I,  ∂e/∂ωᵢ = [q]× (3D), (q_y, −q_x)ᵀ (2D),  ∂e/∂vⱼ = RᵢᵀRⱼ,  ∂e/∂ωⱼ = 0.
template <int kDim>
struct RelativePositionError {
  Eigen::Matrix<double, kDim, 1> position;

  template <class T>
  Eigen::Matrix<T, kDim, 1> operator()(const RigidMotion<T, kDim>& xi,
                                       const RigidMotion<T, kDim>& xj) const {
    return xi.inverseAct(xj.t) - position.template cast<T>();
  }
};
template <class G>
using RelativePositionAutoDiff = AutoDiffFactor<G, RelativePositionError<G::kDim>, G::kDim, 2>;

template <class G>
class RelativePositionFactor final : public BinaryFactorModel<G, G::kDim> {
 public:
  static constexpr int kDim = G::kDim;
  using typename BinaryFactorModel<G, kDim>::Error;
  using typename BinaryFactorModel<G, kDim>::Jacobian;

  explicit RelativePositionFactor(const Eigen::Matrix<double, kDim, 1>& p) : position_(p) {}

  Error error(const G& xi, const G& xj, Jacobian* Ji, Jacobian* Jj) const override {
    const auto Ri = xi.rotation();
    const Error q = Ri.transpose() * (xj.translation() - xi.translation());
    if (Ji) {
      Ji->template leftCols<kDim>() = -Eigen::Matrix<double, kDim, kDim>::Identity();
      if constexpr (kDim == 2)
        Ji->col(2) << q.y(), -q.x();
      else
        Ji->template rightCols<3>() << 0, -q.z(), q.y(), q.z(), 0, -q.x(), -q.y(), q.x(), 0;
    }
    if (Jj) {
      Jj->setZero();
      Jj->template leftCols<kDim>() = Ri.transpose() * xj.rotation();
    }
    return q - position_;
  }
  std::string name() const override { return "relative_position"; }

 private:
  Eigen::Matrix<double, kDim, 1> position_;
};

}  // namespace arbor::examples
