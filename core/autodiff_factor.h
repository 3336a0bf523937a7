// A factor of your own from one error function templated on the scalar, differentiated
// automatically (forward mode, Eigen's AutoDiffScalar with a fixed-size derivative vector of
// arity·kDoF entries), in the style of Ceres' AutoDiffCostFunction:
//
//   struct Range {                       // e = ‖t(x) − a‖ − ρ
//     Eigen::Vector2d a; double rho;
//     template <class T>
//     Eigen::Matrix<T, 1, 1> operator()(const RigidMotion2<T>& x) const {
//       return Eigen::Matrix<T, 1, 1>((x.t - a.cast<T>()).norm() - rho);
//     }
//   };
//   auto model = AutoDiffFactor<SE2, Range, 1>::Create(Range{a, rho}, "range");
//   Factor2 f = CustomFactor<SE2>::make(model, omega, i);
//
// The functor sees each pose as (R, t) in the scalar T. Differentiating through the retraction
// at τ = 0: the pose handed to it is x ⊞ τ = (R·Exp(ω), t + R v) with τ seeded as the
// derivative directions, and since only first derivatives at τ = 0 are taken,
//
//   t(x ⊞ τ) = t + R v,   R(x ⊞ τ) = R (I + [ω]×)   (exact to first order, so exact here),
//
// so the Jacobians are the right-perturbation ones of the built-in factors (tangent order
// [v; ω]). Why Eigen's AutoDiffScalar and not Ceres' Jet: Eigen is already the library's one
// dependency; Ceres is not linked by it (docs/factors.md, for the cost).
#pragma once

#include <memory>
#include <string>
#include <utility>

#include <Eigen/Core>
#include <unsupported/Eigen/AutoDiff>

#include "arbor_slam/core/factor_model.h"

namespace arbor {

/// A pose as a rotation matrix R and a translation t in the scalar T: p ↦ R p + t.
template <class T, int kDim>
struct RigidMotion {
  using Rotation = Eigen::Matrix<T, kDim, kDim>;
  using Point = Eigen::Matrix<T, kDim, 1>;
  Rotation R;
  Point t;

  Point act(const Point& p) const { return R * p + t; }
  /// R ᵀ(p − t): p in this pose's frame.
  Point inverseAct(const Point& p) const { return R.transpose() * (p - t); }
  RigidMotion compose(const RigidMotion& o) const { return {R * o.R, R * o.t + t}; }
  RigidMotion inverse() const { return {R.transpose(), -(R.transpose() * t)}; }
  /// this⁻¹ · o.
  RigidMotion between(const RigidMotion& o) const {
    return {R.transpose() * o.R, R.transpose() * (o.t - t)};
  }
};
template <class T>
using RigidMotion2 = RigidMotion<T, 2>;
template <class T>
using RigidMotion3 = RigidMotion<T, 3>;

/// The factor model of `Functor`, which maps kArity poses (RigidMotion<T, kDim>) to an
/// Eigen::Matrix<T, kRows, 1> for T = double and T = the autodiff scalar.
template <class G, class Functor, int kRows, int kArity = 1>
class AutoDiffFactor final : public FactorModel<G> {
 public:
  static_assert(kRows >= 1 && kRows <= G::kDoF, "a residual has 1..kDoF rows");
  static_assert(kArity == 1 || kArity == 2, "a factor is on one or two poses");
  static constexpr int kDoF = G::kDoF;
  static constexpr int kDim = G::kDim;
  using Derivatives = Eigen::Matrix<double, kArity * kDoF, 1>;
  using Scalar = Eigen::AutoDiffScalar<Derivatives>;

  AutoDiffFactor(Functor functor, std::string name)
      : functor_(std::move(functor)), name_(std::move(name)) {}

  static std::shared_ptr<const FactorModel<G>> Create(Functor functor,
                                                      std::string name = "autodiff") {
    return std::make_shared<const AutoDiffFactor>(std::move(functor), std::move(name));
  }

  const Functor& functor() const { return functor_; }
  int rows() const override { return kRows; }
  int arity() const override { return kArity; }
  std::string name() const override { return name_; }

  void evaluate(const std::array<const G*, 2>& x, typename FactorModel<G>::Residual* e,
                typename FactorModel<G>::Jacobians* J) const override {
    if (!J) {
      *e = call<double>([&](int k) {
        return RigidMotion<double, kDim>{x[k]->rotation(), x[k]->translation()};
      });
      return;
    }
    const Eigen::Matrix<Scalar, kRows, 1> r = call<Scalar>([&](int k) { return seeded(*x[k], k); });
    e->resize(kRows);
    for (int k = 0; k < kArity; ++k) (*J)[static_cast<size_t>(k)].resize(kRows, kDoF);
    for (int row = 0; row < kRows; ++row) {
      (*e)(row) = r(row).value();
      for (int k = 0; k < kArity; ++k)
        (*J)[static_cast<size_t>(k)].row(row) =
            r(row).derivatives().template segment<kDoF>(k * kDoF).transpose();
    }
  }

 private:
  template <class T, class PoseAt>
  Eigen::Matrix<T, kRows, 1> call(const PoseAt& pose) const {
    if constexpr (kArity == 1)
      return functor_(pose(0));
    else
      return functor_(pose(0), pose(1));
  }

  // x ⊞ τ_k at τ_k = 0 with τ_k's entries as derivative directions k·kDoF + [v; ω]:
  // t + R v has ∂/∂v = R; R(I + [ω]×) has ∂/∂ω_b = R [e_b]×.
  static RigidMotion<Scalar, kDim> seeded(const G& x, int k) {
    const Eigen::Matrix<double, kDim, kDim> R = x.rotation();
    const Eigen::Matrix<double, kDim, 1> t = x.translation();
    RigidMotion<Scalar, kDim> p;
    const int v0 = k * kDoF, w0 = v0 + kDim;
    for (int a = 0; a < kDim; ++a) {
      Derivatives d = Derivatives::Zero();
      d.template segment<kDim>(v0) = R.row(a).transpose();
      p.t(a) = Scalar(t(a), d);
    }
    constexpr int kRot = kDoF - kDim;
    std::array<Eigen::Matrix<double, kDim, kDim>, kRot> dR;  // R [e_b]×
    if constexpr (kDim == 2) {
      Eigen::Matrix2d hat;
      hat << 0, -1, 1, 0;
      dR[0] = R * hat;
    } else {
      for (int b = 0; b < 3; ++b) {
        Eigen::Matrix3d hat = Eigen::Matrix3d::Zero();
        const int c = (b + 1) % 3, d = (b + 2) % 3;  // [e_b]×: (d, c) = 1, (c, d) = −1
        hat(d, c) = 1;
        hat(c, d) = -1;
        dR[static_cast<size_t>(b)] = R * hat;
      }
    }
    for (int r = 0; r < kDim; ++r)
      for (int c = 0; c < kDim; ++c) {
        Derivatives d = Derivatives::Zero();
        for (int b = 0; b < kRot; ++b) d(w0 + b) = dR[static_cast<size_t>(b)](r, c);
        p.R(r, c) = Scalar(R(r, c), d);
      }
    return p;
  }

  Functor functor_;
  std::string name_;
};

}  // namespace arbor
