// Powell's dogleg on a Bayes tree (as GTSAM's ISAM2 with ISAM2DoglegParams; Rosen, Kaess,
// Leonard, "RISE: An incremental trust-region method for robust online sparse least-squares
// estimation", T-RO 2014): the Cauchy point from the gradient Aᵀb = Σ_cliques [Rᵀd; Sᵀd],
// blended with the Gauss–Newton step inside the trust region; the radius adapts with
// ρ = actual / predicted decrease of F.
#pragma once

#include <algorithm>
#include <cmath>
#include <vector>

#include <Eigen/Core>

#include "arbor_slam/bayestree/clique.h"

namespace arbor::bayestree {

template <int D>
using Tangents = std::vector<Eigen::Matrix<double, D, 1>>;

template <int D>
void gatherTangents(const Tangents<D>& x, const std::vector<int>& vars, Eigen::VectorXd* out) {
  out->resize(static_cast<Eigen::Index>(vars.size()) * D);
  for (size_t k = 0; k < vars.size(); ++k) out->template segment<D>(k * D) = x[vars[k]];
}

template <int D>
double squaredNorm(const Tangents<D>& x) {
  double s = 0;
  for (const auto& v : x) s += v.squaredNorm();
  return s;
}

/// Σ over the cliques in use of ‖R x_f + S x_s − d‖² (the linear model up to a constant);
/// Σ‖d‖² when x is null (the model at zero).
template <int D>
double bayesNetError(const std::vector<Clique<D>>& cliques, const Tangents<D>* x) {
  double err = 0;
  Eigen::VectorXd xf, xs, r;
  for (const Clique<D>& c : cliques) {
    if (!c.in_use) continue;
    if (!x) {
      err += c.d().squaredNorm();
      continue;
    }
    gatherTangents<D>(*x, c.frontals, &xf);
    gatherTangents<D>(*x, c.separator, &xs);
    r = -c.d();
    r.noalias() += c.R().template triangularView<Eigen::Upper>() * xf;
    if (xs.size() > 0) r.noalias() += c.S() * xs;
    err += r.squaredNorm();
  }
  return err;
}

/// The dogleg step for the tree's Gauss–Newton step `newton`, with `objective(x)` = F at the
/// linearisation point ⊞ x; adapts *radius (not below min_radius). Zero when no step within
/// 60 radius reductions decreases F.
template <int D, class Objective>
Tangents<D> doglegStep(const std::vector<Clique<D>>& cliques, const Tangents<D>& newton,
                       double* radius_inout, double min_radius, const Objective& objective) {
  using Vec = Eigen::Matrix<double, D, 1>;
  const int n = static_cast<int>(newton.size());
  Tangents<D> grad(n, Vec::Zero());
  Eigen::VectorXd gf, gs;
  for (const Clique<D>& c : cliques) {
    if (!c.in_use) continue;
    gf.noalias() = c.R().transpose() * c.d();
    for (size_t a = 0; a < c.frontals.size(); ++a)
      grad[c.frontals[a]] += gf.template segment<D>(a * D);
    if (c.separator.empty()) continue;
    gs.noalias() = c.S().transpose() * c.d();
    for (size_t b = 0; b < c.separator.size(); ++b)
      grad[c.separator[b]] += gs.template segment<D>(b * D);
  }
  const double gg = squaredNorm<D>(grad);
  // ‖A g‖² = Σ ‖R g_f + S g_s‖² (the Bayes net with d = 0).
  double Agg = 0;
  {
    Eigen::VectorXd xf, xs, r;
    for (const Clique<D>& c : cliques) {
      if (!c.in_use) continue;
      gatherTangents<D>(grad, c.frontals, &xf);
      gatherTangents<D>(grad, c.separator, &xs);
      r.noalias() = c.R().template triangularView<Eigen::Upper>() * xf;
      if (xs.size() > 0) r.noalias() += c.S() * xs;
      Agg += r.squaredNorm();
    }
  }
  Tangents<D> dx_u(n, Vec::Zero());
  if (gg > 0 && Agg > 0)
    for (int v = 0; v < n; ++v) dx_u[v] = (gg / Agg) * grad[v];
  const double norm_n = std::sqrt(squaredNorm<D>(newton));
  const double norm_u = std::sqrt(squaredNorm<D>(dx_u));
  const double F0 = objective(Tangents<D>(n, Vec::Zero()));
  const double M0 = bayesNetError<D>(cliques, nullptr);
  double& radius_now = *radius_inout;
  Tangents<D> dx_d(n);
  for (int attempt = 0; attempt < 60; ++attempt) {
    const double radius = radius_now;
    double norm_d;
    if (norm_n <= radius) {
      dx_d = newton;
      norm_d = norm_n;
    } else if (norm_u >= radius) {
      for (int v = 0; v < n; ++v) dx_d[v] = (radius / norm_u) * dx_u[v];
      norm_d = radius;
    } else {  // the point on the segment dx_u → dx_n at distance radius
      double a = 0, b = 0;
      for (int v = 0; v < n; ++v) {
        const Vec diff = newton[v] - dx_u[v];
        a += diff.squaredNorm();
        b += dx_u[v].dot(diff);
      }
      const double cc = norm_u * norm_u - radius * radius;
      const double tau = a > 0 ? (-b + std::sqrt(std::max(b * b - a * cc, 0.0))) / a : 0.0;
      for (int v = 0; v < n; ++v) dx_d[v] = dx_u[v] + tau * (newton[v] - dx_u[v]);
      norm_d = radius;
    }
    const double predicted = M0 - bayesNetError<D>(cliques, &dx_d);
    const double F1 = objective(dx_d);
    const double rho = predicted > 0 ? (F0 - F1) / predicted : (F1 <= F0 ? 1.0 : -1.0);
    if (rho >= 0.75) {
      radius_now = std::max(radius, 3.0 * norm_d);
    } else if (rho < 0.25) {
      radius_now = 0.5 * radius;
    }
    if (rho >= 0 || F1 <= F0) return dx_d;
    if (radius_now < min_radius) break;
  }
  // No step decreases F: stay at the linearisation point.
  radius_now = std::max(radius_now, min_radius);
  return Tangents<D>(n, Vec::Zero());
}

}  // namespace arbor::bayestree
