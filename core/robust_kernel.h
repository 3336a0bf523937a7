// Robust kernels on a factor's squared whitened residual s = ‖r‖² = eᵀΩe, and the graduated
// (GNC) surrogates of Yang, Antonante, Tzoumas, Carlone, "Graduated Non-Convexity for Robust
// Spatial Perception: From Non-Minimal Solvers to Global Outlier Rejection", RA-L 2020.
//
// Convention. Every kernel is a function ρ(s) of s = ‖r‖², not of ‖r‖, with ρ(s) = s near 0
// (so a kernel changes nothing for small residuals and w → 1 there), and its threshold c is on
// the whitened residual norm: the kernel departs from least squares at s = c². Working in s
// keeps the IRLS weight a plain derivative, w(s) = ρ′(s): the gradient of Σ ρ(s_k) is
// Σ ρ′(s_k) ∇s_k, the gradient of the weighted least squares Σ w_k s_k at fixed w_k, so one
// iteratively reweighted step scales the factor's whitened A and r by √w (Black & Rangarajan,
// "On the Unification of Line Processes, Outlier Rejection, and Robust Statistics with
// Applications in Early Vision", IJCV 1996: the outlier process w ∈ [0, 1]). Because s is a
// whitened χ²-distributed quantity for an inlier (kDoF degrees of freedom), the field's usual
// threshold is a χ² quantile: chiSquareThreshold(0.95, 3) = 7.81 is c² for a 2D relative pose.
//
//   none     ρ(s) = s                               w = 1
//   Huber    ρ(s) = s (s ≤ c²),  2c√s − c² (else)    w = 1, c/√s
//   Cauchy   ρ(s) = c² log(1 + s/c²)                 w = 1/(1 + s/c²)
//   Geman–McClure, with GNC's μ (Yang et al.'s GM surrogate; Black & Rangarajan's ρ at μ = 1):
//            ρ_μ(s) = μc² s / (μc² + s)              w = (μc² / (μc² + s))²
//            μ → ∞: ρ → s (convex); μ = 1: Geman–McClure. GNC starts at μ₀ = 2 s_max / c² and
//            divides μ by 1.4 each step down to 1 (Yang et al., Algorithm 1 and its remarks).
//   TLS, with GNC's μ (Yang et al.'s TLS surrogate):
//            ρ_μ(s) = s                              s ≤ μ/(μ+1) c²
//                     2c√(μ(μ+1)) √s − μ(c² + s)     μ/(μ+1) c² ≤ s ≤ (μ+1)/μ c²
//                     c²                             s ≥ (μ+1)/μ c²
//            w = 1,  c√(μ(μ+1))/√s − μ,  0 (the paper's closed-form weight update)
//            μ → 0: convex; μ → ∞: ρ = min(s, c²), w ∈ {0, 1}. GNC starts at μ₀ = c² /
//            (2 s_max − c²) and multiplies μ by 1.4 each step (as above).
// derivative() is dw/ds = ρ″(s), for tests and for a solver that wants the second-order term.
#pragma once

#include <limits>
#include <string>

namespace arbor {

enum class KernelKind { kNone, kHuber, kCauchy, kGemanMcClure, kTruncatedLeastSquares };

std::string toString(KernelKind kind);  ///< "none", "huber", "cauchy", "gm", "tls"
/// Inverse of toString; throws std::invalid_argument naming the value and the valid names.
KernelKind parseKernelKind(const std::string& name);

/// c² such that P(χ²_dof ≤ c²) = confidence (Boost.Math's χ² quantile). Throws
/// std::invalid_argument unless 0 < confidence < 1 and dof ≥ 1.
double chiSquareThreshold(double confidence, int dof);

/// One kernel on s = ‖r‖² (a value type: kind, threshold c², GNC parameter μ).
struct RobustKernel {
  KernelKind kind = KernelKind::kNone;
  /// c², the threshold on s (ignored by kNone). Must be > 0 for the other kinds.
  double threshold = 1.0;
  /// GNC's control parameter μ for kGemanMcClure and kTruncatedLeastSquares (ignored by the
  /// others). The default is the kernel itself: μ = 1 for GM, μ = ∞ for TLS.
  double mu = std::numeric_limits<double>::infinity();

  static RobustKernel none() { return {}; }
  static RobustKernel huber(double c2) { return {KernelKind::kHuber, c2, 1.0}; }
  static RobustKernel cauchy(double c2) { return {KernelKind::kCauchy, c2, 1.0}; }
  static RobustKernel gemanMcClure(double c2, double mu = 1.0) {
    return {KernelKind::kGemanMcClure, c2, mu};
  }
  static RobustKernel tls(double c2, double mu = std::numeric_limits<double>::infinity()) {
    return {KernelKind::kTruncatedLeastSquares, c2, mu};
  }

  bool isNone() const { return kind == KernelKind::kNone; }
  /// Has a GNC parameter (GM and TLS).
  bool isGraduated() const {
    return kind == KernelKind::kGemanMcClure || kind == KernelKind::kTruncatedLeastSquares;
  }

  double rho(double s) const;         ///< ρ(s)
  double weight(double s) const;      ///< w(s) = ρ′(s), in [0, 1]
  double derivative(double s) const;  ///< w′(s) = ρ″(s)
  /// The least weight of an inlier: the kernel's own weight at s = c² (Huber 1, Cauchy ½,
  /// Geman–McClure ¼ at μ = 1), so that at the kernel a factor is an inlier iff s ≤ c², the
  /// threshold's meaning; ½ for TLS (its weights end in {0, 1}; inside the band the surrogate's
  /// weight crosses ½ near s = c²) and for none.
  double inlierCut() const;

  /// GNC's first μ for the largest residual s_max of the factors it weights (Yang et al.;
  /// for TLS, s_max ≤ c²/2 gives +∞: everything is an inlier already).
  double initialMu(double s_max) const;
  /// μ after one GNC step: ×1.4 for TLS, ÷1.4 for GM, floored at 1 (the kernel itself).
  double nextMu(double factor = 1.4) const;
  /// μ has reached the kernel itself (GM: μ ≤ 1; TLS: μ = ∞); always true for the others.
  bool atKernel() const;
  /// Why the kernel cannot be used, or "": a threshold that is not finite and > 0, a NaN μ or
  /// μ ≤ 0 for GM/TLS.
  std::string problem() const;
};

}  // namespace arbor
