// Pieces shared by the tests of factors of your own (custom_factor_test.cc,
// custom_factor_solvers_test.cc): random poses, points and information, the example range
// model, a trajectory, and a dense Gauss–Newton step over any factors.
#pragma once

#include <memory>
#include <random>
#include <vector>

#include <Eigen/Cholesky>
#include <Eigen/Core>

#include "arbor_slam/core/example_factors.h"
#include "arbor_slam/core/factor.h"
#include "arbor_slam/tests/random_graphs.h"

namespace arbor::testing {

template <class G>
G randomPose(std::mt19937_64& rng) {
  return G::Exp(randomTangent<G>(rng, 3.0, 1.0));
}

template <int m>
Eigen::Matrix<double, m, m> randomSpd(std::mt19937_64& rng) {
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  Eigen::Matrix<double, m, m> b;
  for (int k = 0; k < b.size(); ++k) b.data()[k] = u(rng);
  return b * b.transpose() + 5.0 * Eigen::Matrix<double, m, m>::Identity();
}

template <class G>
Eigen::Matrix<double, G::kDim, 1> randomPoint(std::mt19937_64& rng, double scale) {
  std::uniform_real_distribution<double> u(-scale, scale);
  Eigen::Matrix<double, G::kDim, 1> p;
  for (int k = 0; k < G::kDim; ++k) p(k) = u(rng);
  return p;
}

template <class G>
std::shared_ptr<const FactorModel<G>> rangeModel(const Eigen::Matrix<double, G::kDim, 1>& a,
                                                 double range) {
  return examples::RangeFactor<G>::Create({a, range}, "range");
}

/// Dense Gauss–Newton step over the poses not fixed (zero for fixed ones) for any factors, each
/// scaled by its inlier weight (linearizeWeighted), as tests/smoother_priors_test.cc's.
template <class G>
std::vector<typename G::Tangent> denseStep(const std::vector<Factor<G>>& factors,
                                           const std::vector<G>& x,
                                           const std::vector<char>& fixed = {}) {
  constexpr int D = G::kDoF;
  const int n = static_cast<int>(x.size());
  std::vector<int> col(n, -1);
  int m = 0;
  for (int k = 0; k < n; ++k)
    if (fixed.empty() || !fixed[k]) col[k] = m++;
  Eigen::MatrixXd H = Eigen::MatrixXd::Zero(m * D, m * D);
  Eigen::VectorXd b = Eigen::VectorXd::Zero(m * D);
  for (const Factor<G>& f : factors) {
    typename Factor<G>::Linearization L;
    f.linearizeWeighted(x, &L);
    for (int k = 0; k < f.arity(); ++k) {
      const int ck = col[f.key(k)];
      if (ck < 0) continue;
      b.segment<D>(ck * D) -= L.A[k].transpose() * L.r;
      for (int l = 0; l < f.arity(); ++l) {
        const int cl = col[f.key(l)];
        if (cl >= 0) H.block<D, D>(ck * D, cl * D) += L.A[k].transpose() * L.A[l];
      }
    }
  }
  const Eigen::VectorXd dx = H.llt().solve(b);
  std::vector<typename G::Tangent> out(n, G::Tangent::Zero());
  for (int k = 0; k < n; ++k)
    if (col[k] >= 0) out[k] = dx.segment<D>(col[k] * D);
  return out;
}

template <class G>
std::vector<G> trajectory(int n, std::mt19937_64& rng) {
  std::vector<G> x(n);
  for (int k = 1; k < n; ++k) {
    typename G::Tangent t = randomTangent<G>(rng, 0.2, 0.2);
    t(0) += 1.0;
    x[k] = x[k - 1].compose(G::Exp(t));
  }
  return x;
}

/// A world with custom factors: odometry edges, a pose prior on pose 0, ranges to anchors every
/// 3rd pose, relative positions as loop closures, and (3D) planar motion every 5th pose.

}  // namespace arbor::testing
