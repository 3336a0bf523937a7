// Pieces shared by tests that build random pose graphs in code.
#pragma once

#include <random>
#include <vector>

#include "arbor_slam/core/pose_graph.h"

namespace arbor::testing {

/// A random tangent vector: N(0, translation²) on the translational part, N(0, rotation²) on
/// the rotational part.
template <class G>
typename G::Tangent randomTangent(std::mt19937_64& rng, double translation, double rotation) {
  std::normal_distribution<double> n(0.0, 1.0);
  typename G::Tangent tau;
  for (int k = 0; k < G::kDoF; ++k) tau(k) = n(rng) * (k < G::kDim ? translation : rotation);
  return tau;
}

/// A random information matrix: diagonal precisions (translation 20, rotation 200) plus a random
/// symmetric positive-semidefinite coupling, so Ω is dense, anisotropic and positive definite.
template <class G>
typename RelativePoseEdge<G>::Matrix randomInformation(std::mt19937_64& rng) {
  using M = typename RelativePoseEdge<G>::Matrix;
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  M b;
  for (int r = 0; r < G::kDoF; ++r)
    for (int c = 0; c < G::kDoF; ++c) b(r, c) = u(rng);
  M omega = 2.0 * b * b.transpose();
  for (int k = 0; k < G::kDoF; ++k) omega(k, k) += k < G::kDim ? 20.0 : 200.0;
  return omega;
}

/// Diagonal information: t on the translational entries, r on the rotational ones.
template <class G>
typename RelativePoseEdge<G>::Matrix diagonalInformation(double t, double r) {
  typename RelativePoseEdge<G>::Matrix m = RelativePoseEdge<G>::Matrix::Zero();
  for (int k = 0; k < G::kDoF; ++k) m(k, k) = k < G::kDim ? t : r;
  return m;
}

/// A tangent vector with every entry N(0, sigma²).
template <class G>
typename G::Tangent isotropicNoise(std::mt19937& rng, double sigma) {
  std::normal_distribution<double> n(0.0, sigma);
  typename G::Tangent t;
  for (int k = 0; k < G::kDoF; ++k) t(k) = n(rng);
  return t;
}

/// A graph with its ground truth.
template <class G>
struct Synthetic {
  PoseGraph<G> graph;
  std::vector<G> truth;
};

}  // namespace arbor::testing
