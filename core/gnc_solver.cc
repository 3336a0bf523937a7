#include "arbor/core/gnc_solver.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <stdexcept>
#include <utility>

namespace arbor {
namespace {

using Clock = std::chrono::steady_clock;

void checkOptions(const GncOptions& o, int edges) {
  if (o.kernel == KernelKind::kNone)
    throw std::invalid_argument("GncOptions.kernel must be tls, gm, cauchy or huber, not none");
  if (o.threshold > 0 && !std::isfinite(o.threshold))
    throw std::invalid_argument("GncOptions.threshold must be finite, got " +
                                std::to_string(o.threshold));
  if (!(o.threshold > 0)) chiSquareThreshold(o.confidence, 1);  // throws on a bad confidence
  if (!(o.mu_factor > 1.0))
    throw std::invalid_argument("GncOptions.mu_factor must be > 1, got " +
                                std::to_string(o.mu_factor));
  for (const auto& [name, value] :
       {std::pair<const char*, double>{"weight_tolerance", o.weight_tolerance},
        {"cost_tolerance", o.cost_tolerance},
        {"min_initial_mu", o.min_initial_mu}})
    if (!(value >= 0) || !std::isfinite(value))
      throw std::invalid_argument(std::string("GncOptions.") + name +
                                  " must be finite and >= 0, got " + std::to_string(value));
  if (o.max_iterations < 1 || o.max_rounds < 1)
    throw std::invalid_argument("GncOptions.max_iterations and max_rounds must be >= 1");
  if (!o.trusted.empty() && static_cast<int>(o.trusted.size()) != edges)
    throw std::invalid_argument("GncOptions.trusted has " + std::to_string(o.trusted.size()) +
                                " marks for " + std::to_string(edges) + " edges");
}

template <class G>
std::vector<double> edgeCosts(const PoseGraph<G>& graph, const std::vector<G>& poses) {
  std::vector<double> s(graph.edges.size());
  for (size_t k = 0; k < s.size(); ++k) {
    const auto& e = graph.edges[k];
    s[k] = e.cost(poses[e.i], poses[e.j]);
  }
  return s;
}

// σ̂² = Σ_{k inlier} s_k + priors' Σ eᵀΩe over the redundancy (rows − unknowns), or 1 when the
// inlier problem has no redundancy.
template <class G>
double varianceFactor(const PoseGraph<G>& graph, const std::vector<G>& poses,
                      const std::vector<double>& s, const std::vector<char>& inlier) {
  double f = 0.0, rows = 0.0;
  for (size_t k = 0; k < s.size(); ++k) {
    if (!inlier[k]) continue;
    f += s[k];
    rows += G::kDoF;
  }
  for (const auto& p : graph.pose_priors) {
    f += p.cost(poses[p.i]);
    rows += G::kDoF;
  }
  for (const auto& p : graph.position_priors) {
    f += p.cost(poses[p.i]);
    rows += G::kDim;
  }
  const double unknowns =
      static_cast<double>(G::kDoF) * (graph.numPoses() - graph.gaugeIndices().size());
  const double redundancy = rows - unknowns;
  if (!(redundancy > 0) || !(f > 0)) return 1.0;
  return f / redundancy;
}

}  // namespace

template <class G>
PoseGraph<G> keepEdges(const PoseGraph<G>& graph, const std::vector<char>& keep) {
  if (keep.size() != graph.edges.size())
    throw std::invalid_argument("keepEdges: " + std::to_string(keep.size()) + " marks for " +
                                std::to_string(graph.edges.size()) + " edges");
  PoseGraph<G> out;
  out.ids = graph.ids;
  out.index = graph.index;
  out.poses = graph.poses;
  out.pose_priors = graph.pose_priors;
  out.position_priors = graph.position_priors;
  out.fixed = graph.fixed;
  out.has_initial_estimate = graph.has_initial_estimate;
  for (size_t k = 0; k < keep.size(); ++k)
    if (keep[k]) out.edges.push_back(graph.edges[k]);
  return out;
}

template <class G>
GncResult solveGnc(const PoseGraph<G>& graph, std::vector<G>* poses, const GncOptions& options) {
  const Clock::time_point start = Clock::now();
  const int m = graph.numEdges();
  checkOptions(options, m);
  if (!poses || static_cast<int>(poses->size()) != graph.numPoses())
    throw std::invalid_argument("solveGnc: " + std::to_string(poses ? poses->size() : 0) +
                                " poses for a graph of " + std::to_string(graph.numPoses()));
  GncResult result;
  result.trusted.assign(m, 0);
  for (int k = 0; k < m; ++k) {
    const auto& e = graph.edges[k];
    result.trusted[k] = (options.trust_odometry && std::abs(e.i - e.j) == 1) ||
                        (!options.trusted.empty() && options.trusted[k]);
    if (!result.trusted[k]) ++result.candidates;
  }

  BatchOptions inner = options.inner, outer = options.outer;
  inner.cancel = outer.cancel = options.cancel;
  const std::vector<G> x_init = *poses;
  const std::vector<double> s_init = edgeCosts(graph, x_init);
  WeightedBatchSolver<G> solver(graph);
  std::vector<double>& w = result.weights;
  w.assign(m, 1.0);
  // x⁰: plain least squares from x_init (Algorithm 1, line 1).
  const BatchSummary ls = solver.solve(w, poses, outer);
  result.lm_iterations += ls.iterations;
  result.cancelled = ls.termination == Termination::kCancelled;
  result.F_least_squares = ls.F_final;
  const std::vector<G> x_ls = *poses;
  std::vector<double> s = edgeCosts(graph, *poses);

  const bool given = options.threshold > 0;
  const bool automatic = !given && options.estimate_scale;
  const double quantile = given ? 0.0 : chiSquareThreshold(options.confidence, G::kDoF);
  std::vector<char> inlier(m, 1);
  result.scale = automatic ? varianceFactor(graph, *poses, s, inlier) : 1.0;
  result.threshold = given ? options.threshold : quantile * result.scale;
  const bool restart = options.inner_start == GncInnerStart::kInitial;

  RobustKernel kernel{options.kernel, result.threshold, 1.0};
  for (int round = 0; !result.cancelled && round < options.max_rounds; ++round) {
    ++result.rounds;
    kernel.threshold = result.threshold;
    if (round > 0) {  // a new threshold: GNC again from the start, at x⁰'s residuals
      *poses = x_ls;
      s = edgeCosts(graph, *poses);
    }
    result.converged = false;
    bool done = false;
    if (kernel.isGraduated()) {
      // μ⁰ (Remark 5) from the largest weighted residual at x_init (GTSAM) or x⁰.
      const std::vector<double>& s0 = options.mu_start == GncMuStart::kInitial ? s_init : s;
      double s_max = 0.0;
      for (int k = 0; k < m; ++k)
        if (!result.trusted[k]) s_max = std::max(s_max, s0[k]);
      kernel.mu = kernel.initialMu(s_max);
      // x⁰ with every weighted s_k(x⁰) ≤ c² is a local minimum of Σ min(s_k, c²) (there TLS is
      // least squares, and x⁰ minimises it): TLS's answer, whatever μ⁰ says; GTSAM stops likewise
      // when s_max ≤ c²/2 at its initial values.
      double s_max_ls = 0.0;
      for (int k = 0; k < m; ++k)
        if (!result.trusted[k]) s_max_ls = std::max(s_max_ls, s[k]);
      if (kernel.kind == KernelKind::kTruncatedLeastSquares) {
        if (std::isinf(kernel.mu) || s_max_ls <= kernel.threshold) {
          std::fill(w.begin(), w.end(), 1.0);
          result.converged = done = true;
          result.message = "every residual within c² at the least-squares start";
        }
        kernel.mu = std::max(kernel.mu, options.min_initial_mu);
      }
    }
    // F_w,prev: at the first step the least-squares objective (GTSAM's prev_cost).
    double previous_cost = ls.F_final;
    std::vector<double> previous(m, -1.0);
    for (int it = 0; !done && it < options.max_iterations; ++it) {
      if (options.cancel.cancelled()) {
        result.cancelled = true;
        break;
      }
      ++result.iterations;
      // The closed-form weight update at the current estimate (trusted edges stay at 1).
      bool binary = true;
      double change = 0.0;
      for (int k = 0; k < m; ++k) {
        if (result.trusted[k]) continue;
        w[k] = kernel.weight(s[k]);
        if (std::min(w[k], 1.0 - w[k]) > options.weight_tolerance) binary = false;
        change = std::max(change, std::abs(w[k] - previous[k]));
      }
      if (!kernel.isGraduated() && change <= options.weight_tolerance) {
        result.converged = true;
        result.message = "weights converged";
        break;
      }
      previous = w;
      const std::vector<G> finished = *poses;  // the last step's estimate, kept if cancelled
      if (restart && kernel.isGraduated()) *poses = x_init;
      const BatchSummary step = solver.solve(w, poses, inner);
      result.lm_iterations += step.iterations;
      if (step.termination == Termination::kCancelled) {
        *poses = finished;
        result.cancelled = true;
        break;
      }
      s = edgeCosts(graph, *poses);
      const double cost = step.F_final;
      if (options.verbose) {
        int out = 0;
        for (int k = 0; k < m; ++k) out += !result.trusted[k] && w[k] <= 0.5;
        std::fprintf(stderr,
                     "gnc round %d step %3d  c² %.4g  μ %.4g  weighted F %.10e  outliers %d  "
                     "max Δw %.3g  inner %d (%s)\n",
                     round, it, kernel.threshold, kernel.mu, cost, out, change, step.iterations,
                     toString(step.termination).c_str());
      }
      if (!kernel.isGraduated()) continue;
      // GTSAM's checkConvergence, on the weights this step solved with and its cost.
      if (kernel.kind == KernelKind::kTruncatedLeastSquares && binary) {
        result.converged = true;
        result.message = "weights binary";
        break;
      }
      if (kernel.kind == KernelKind::kGemanMcClure && kernel.atKernel()) {
        result.converged = true;
        result.message = "μ at the kernel";
        break;
      }
      if (std::abs(cost - previous_cost) / std::max(previous_cost, 1e-7) < options.cost_tolerance) {
        result.converged = true;
        result.message = "weighted cost converged";
        break;
      }
      previous_cost = cost;
      kernel.mu = kernel.nextMu(options.mu_factor);
    }
    if (!result.converged) result.message = "GNC iteration limit reached";
    for (int k = 0; k < m; ++k) inlier[k] = result.trusted[k] || w[k] > 0.5;
    if (!automatic || result.cancelled) break;
    const double scale = varianceFactor(graph, *poses, s, inlier);
    const double threshold = quantile * scale;
    const double moved = std::abs(threshold - result.threshold) / result.threshold;
    if (options.verbose)
      std::fprintf(stderr, "gnc round %d: σ̂² %.4g → %.4g, c² %.4g → %.4g\n", round, result.scale,
                   scale, result.threshold, threshold);
    if (moved <= options.scale_tolerance) break;
    result.scale = scale;
    result.threshold = threshold;
  }
  result.mu = kernel.mu;

  // The inlier problem: the edges kept, each with weight 1, from the GNC estimate.
  std::vector<double> binary(m);
  for (int k = 0; k < m; ++k) binary[k] = inlier[k] ? 1.0 : 0.0;
  if (!result.cancelled) {
    const BatchSummary last = solver.solve(binary, poses, outer);
    result.lm_iterations += last.iterations;
    result.cancelled = last.termination == Termination::kCancelled;
  }
  if (result.cancelled) {
    result.converged = false;
    result.message = "cancelled after " + std::to_string(result.iterations) + " GNC steps";
  }
  s = edgeCosts(graph, *poses);
  result.inlier = inlier;
  result.rejected = 0;
  result.F_all = objective(graph, *poses);
  result.F_inliers = weightedObjective(graph, binary, *poses);
  result.robust_cost = result.F_inliers;
  for (int k = 0; k < m; ++k) {
    if (!inlier[k]) ++result.rejected;
    if (!result.trusted[k]) result.robust_cost += kernel.rho(s[k]) - (inlier[k] ? s[k] : 0.0);
  }
  result.time_s = std::chrono::duration<double>(Clock::now() - start).count();
  return result;
}

template <class G>
CertifiedInliers certifyInliers(const PoseGraph<G>& graph, GncResult* gnc, std::vector<G>* poses,
                                const RtrOptions& options, int max_passes) {
  CertifiedInliers out;
  const int m = graph.numEdges();
  for (int pass = 0; pass < max_passes; ++pass) {
    const PoseGraph<G> inliers = keepEdges(graph, gnc->inlier);
    out.rtr = solveRtr(inliers, poses, options);
    ++out.passes;
    const std::vector<double> s = edgeCosts(graph, *poses);
    int taken = 0;
    for (int k = 0; k < m; ++k) {
      if (gnc->inlier[k] || !(s[k] <= gnc->threshold)) continue;
      gnc->inlier[k] = 1;
      gnc->weights[k] = 1.0;
      ++taken;
    }
    out.readmitted += taken;
    if (taken == 0) break;
  }
  std::vector<double> binary(m);
  gnc->rejected = 0;
  for (int k = 0; k < m; ++k) {
    binary[k] = gnc->inlier[k] ? 1.0 : 0.0;
    gnc->rejected += !gnc->inlier[k];
  }
  gnc->F_all = objective(graph, *poses);
  gnc->F_inliers = weightedObjective(graph, binary, *poses);
  return out;
}

template GncResult solveGnc(const PoseGraph<SE2>&, std::vector<SE2>*, const GncOptions&);
template GncResult solveGnc(const PoseGraph<SE3>&, std::vector<SE3>*, const GncOptions&);
template CertifiedInliers certifyInliers(const PoseGraph<SE2>&, GncResult*, std::vector<SE2>*,
                                         const RtrOptions&, int);
template CertifiedInliers certifyInliers(const PoseGraph<SE3>&, GncResult*, std::vector<SE3>*,
                                         const RtrOptions&, int);
template PoseGraph<SE2> keepEdges(const PoseGraph<SE2>&, const std::vector<char>&);
template PoseGraph<SE3> keepEdges(const PoseGraph<SE3>&, const std::vector<char>&);

}  // namespace arbor
