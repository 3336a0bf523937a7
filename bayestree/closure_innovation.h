// How far a loop closure is from what the rest of the graph predicts, read off the Bayes tree.
// With r the closure's whitened residual at the smoother's estimate, A its whitened Jacobian on
// its two poses (at the linearisation point) and Σ their joint covariance in the tree
// (IncrementalSmoother::predictionCovariance gives AΣAᵀ, one forward substitution along the two
// poses' paths to the root):
//
//   (E) for a closure the tree does not hold (new, or at weight 0): its innovation
//         m = rᵀ (I + A Σ Aᵀ)⁻¹ r,
//       what adding it at weight 1 raises the linearised objective by.
//   (L) for a closure the tree holds at weight 1: its leave-one-out innovation
//         m₋ = rᵀ (I − A Σ Aᵀ)⁻¹ r,
//       (E) of the graph without it. With Σ₋ the covariance without it, Σ⁻¹ = Σ₋⁻¹ + AᵀA, so
//       I + AΣ₋Aᵀ = (I − AΣAᵀ)⁻¹; and one Gauss–Newton step adding it moves the residual from r₋
//       to r = (I − AΣAᵀ) r₋. Hence m₋ = r₋ᵀ (I + AΣ₋Aᵀ)⁻¹ r₋ = rᵀ (I − AΣAᵀ)⁻¹ r: what keeping
//       it costs the whole linearised objective, to first order.
//   (E) from below, without Σ_ab: with B = 2 (A_i Σ_ii A_iᵀ + A_j Σ_jj A_jᵀ) ⪰ A Σ Aᵀ
//       (IncrementalSmoother::predictionCovarianceBound), (I + A Σ Aᵀ)⁻¹ ⪰ (I + B)⁻¹, so
//         m ≥ m_lb = rᵀ (I + B)⁻¹ r.
//       A closure with m_lb past a bound is past it by (E) too, from the two poses' marginals
//       alone (kept from one walk down the tree) instead of their path solves.
//
// The online GNC (bayestree/online_gnc.h) judges closures by them.
#pragma once

#include <optional>

#include "arbor_slam/bayestree/incremental_smoother.h"
#include "arbor_slam/core/factor.h"

namespace arbor {

/// (E): std::nullopt when a pose of the edge has not been through an update (no Σ) or m is not
/// finite.
/// `paths`: how AΣAᵀ is read (IncrementalSmoother::PredictionPaths; kKept for many closures
/// judged on one tree).
template <class G>
std::optional<double> closureInnovation(const IncrementalSmoother<G>& smoother,
                                        const RelativePoseEdge<G>& edge,
                                        typename IncrementalSmoother<G>::PredictionPaths paths =
                                            IncrementalSmoother<G>::PredictionPaths::kOnce);

/// m_lb ≤ (E) (above): std::nullopt where (E) would be.
template <class G>
std::optional<double> closureInnovationLowerBound(const IncrementalSmoother<G>& smoother,
                                                  const RelativePoseEdge<G>& edge);

/// (L): std::nullopt when a pose has no Σ, I − AΣAᵀ is not positive definite (the edge is not
/// in the tree at weight 1: it cannot explain more than all of its own residual) or m₋ is not
/// finite.
template <class G>
std::optional<double> leaveOneOutInnovation(const IncrementalSmoother<G>& smoother,
                                            const RelativePoseEdge<G>& edge,
                                            typename IncrementalSmoother<G>::PredictionPaths paths =
                                                IncrementalSmoother<G>::PredictionPaths::kOnce);

extern template std::optional<double> closureInnovation(const IncrementalSmoother<SE2>&,
                                                        const RelativePoseEdge<SE2>&,
                                                        IncrementalSmoother<SE2>::PredictionPaths);
extern template std::optional<double> closureInnovation(const IncrementalSmoother<SE3>&,
                                                        const RelativePoseEdge<SE3>&,
                                                        IncrementalSmoother<SE3>::PredictionPaths);
extern template std::optional<double> closureInnovationLowerBound(const IncrementalSmoother<SE2>&,
                                                                  const RelativePoseEdge<SE2>&);
extern template std::optional<double> closureInnovationLowerBound(const IncrementalSmoother<SE3>&,
                                                                  const RelativePoseEdge<SE3>&);
extern template std::optional<double> leaveOneOutInnovation(
    const IncrementalSmoother<SE2>&, const RelativePoseEdge<SE2>&,
    IncrementalSmoother<SE2>::PredictionPaths);
extern template std::optional<double> leaveOneOutInnovation(
    const IncrementalSmoother<SE3>&, const RelativePoseEdge<SE3>&,
    IncrementalSmoother<SE3>::PredictionPaths);

}  // namespace arbor
