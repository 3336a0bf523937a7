#include "arbor_slam/core/gnc_solver.h"

#include <algorithm>
#include <array>
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
  if (!o.known_outliers.empty() && static_cast<int>(o.known_outliers.size()) != edges)
    throw std::invalid_argument("GncOptions.known_outliers has " +
                                std::to_string(o.known_outliers.size()) + " marks for " +
                                std::to_string(edges) + " edges");
  if (!o.kernels.empty() && static_cast<int>(o.kernels.size()) != edges)
    throw std::invalid_argument("GncOptions.kernels has " + std::to_string(o.kernels.size()) +
                                " kernels for " + std::to_string(edges) + " edges");
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
  for (const auto& c : graph.custom_factors) {
    f += c.cost(poses);
    rows += c.rows();
  }
  const double unknowns =
      static_cast<double>(G::kDoF) * (graph.numPoses() - graph.gaugeIndices().size());
  const double redundancy = rows - unknowns;
  if (!(redundancy > 0) || !(f > 0)) return 1.0;
  return f / redundancy;
}

// Takes back every rejected edge whose s is within `threshold` (weight 1, inlier); returns how
// many (certifyInliers' and readmitFitting's pass).
int takeBackFitting(const std::vector<double>& s, double threshold, GncResult* gnc) {
  int taken = 0;
  for (size_t k = 0; k < s.size(); ++k) {
    if (gnc->inlier[k] || !(s[k] <= threshold)) continue;
    gnc->inlier[k] = 1;
    gnc->weights[k] = 1.0;
    ++taken;
  }
  return taken;
}

// 1 for an inlier, 0 for an outlier: the inlier problem's weights.
std::vector<double> inlierWeights(const GncResult& gnc) {
  std::vector<double> binary(gnc.inlier.size());
  for (size_t k = 0; k < binary.size(); ++k) binary[k] = gnc.inlier[k] ? 1.0 : 0.0;
  return binary;
}

// The rejected count and the F figures of gnc's classification at `poses`.
template <class G>
void recountClassification(const PoseGraph<G>& graph, const std::vector<G>& poses, GncResult* gnc) {
  gnc->rejected = 0;
  for (char in : gnc->inlier) gnc->rejected += !in;
  gnc->F_all = objective(graph, poses);
  gnc->F_inliers = weightedObjective(graph, inlierWeights(*gnc), poses);
}

}  // namespace

template <class G>
bool trustedEdge(const PoseGraph<G>& graph, const GncOptions& options, int k) {
  const auto& e = graph.edges[static_cast<size_t>(k)];
  return (options.trust_odometry && std::abs(e.i - e.j) == 1) ||
         (!options.trusted.empty() && options.trusted[static_cast<size_t>(k)]);
}

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
  out.custom_factors = graph.custom_factors;
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
  // Known outliers: weight 0 throughout (GTSAM's knownOutliers).
  std::vector<char> fixed_out(m, 0);
  // Each weighted edge's kernel kind: its own (GncOptions::kernels) or options.kernel.
  std::vector<KernelKind> kind(m, options.kernel);
  bool any_graduated = false, all_tls = true;
  for (int k = 0; k < m; ++k) {
    const auto& e = graph.edges[k];
    result.trusted[k] = trustedEdge(graph, options, k);
    if (!options.kernels.empty() && options.kernels[k] != KernelKind::kNone)
      kind[k] = options.kernels[k];
    if (!options.known_outliers.empty() && options.known_outliers[k]) {
      if (result.trusted[k])
        throw std::invalid_argument("solveGnc: edge " + std::to_string(k) + " (" +
                                    std::to_string(e.i) + ", " + std::to_string(e.j) +
                                    ") is both trusted and a known outlier");
      fixed_out[k] = 1;
    }
    if (result.trusted[k]) continue;
    ++result.candidates;
    const RobustKernel probe{kind[k], 1.0, 1.0};
    any_graduated = any_graduated || probe.isGraduated();
    all_tls = all_tls && kind[k] == KernelKind::kTruncatedLeastSquares;
  }

  BatchOptions inner = options.inner, outer = options.outer;
  inner.cancel = outer.cancel = options.cancel;
  const std::vector<G> x_init = *poses;
  const std::vector<double> s_init = edgeCosts(graph, x_init);
  WeightedBatchSolver<G> solver(graph);
  std::vector<double>& w = result.weights;
  w.assign(m, 1.0);
  for (int k = 0; k < m; ++k)
    if (fixed_out[k]) w[k] = 0.0;
  // The edges whose weight GNC moves: neither trusted nor known outliers.
  auto judged = [&](int k) { return !result.trusted[k] && !fixed_out[k]; };
  // x⁰: plain least squares from x_init (Algorithm 1, line 1).
  const BatchSummary ls = solver.solve(w, poses, outer);
  result.lm_iterations += ls.iterations;
  result.cancelled = ls.termination == Termination::kCancelled;
  result.F_least_squares = ls.F_final;
  const std::vector<G> x_ls = *poses;
  std::vector<double> s = edgeCosts(graph, *poses);
  std::vector<char> inlier(m, 1);
  for (int k = 0; k < m; ++k) inlier[k] = !fixed_out[k];
  const bool restart = options.inner_start == GncInnerStart::kInitial;
  // The threshold: given, the χ² quantile, or that quantile times the variance factor σ̂²
  // (estimate_scale), re-estimated over the inliers between rounds (header comment).
  const bool given = options.threshold > 0;
  const bool automatic = !given && options.estimate_scale;
  const double quantile = given ? 0.0 : chiSquareThreshold(options.confidence, G::kDoF);
  result.scale = automatic ? varianceFactor(graph, *poses, s, inlier) : 1.0;
  result.threshold = given ? options.threshold : quantile * result.scale;

  std::array<RobustKernel, 5> kernels;
  for (int round = 0; !result.cancelled && round < options.max_rounds; ++round) {
    ++result.rounds;
    if (round > 0) {  // a new threshold: GNC again from the start, at x⁰'s residuals
      *poses = x_ls;
      s = edgeCosts(graph, *poses);
    }
    // One kernel per kind in use, each with its own μ (μ⁰ from the largest residual of its edges).
    for (int c = 0; c < 5; ++c) {
      kernels[c] = RobustKernel{static_cast<KernelKind>(c), result.threshold, 1.0};
      if (!kernels[c].isGraduated()) continue;
      const std::vector<double>& s0 = options.mu_start == GncMuStart::kInitial ? s_init : s;
      double s_max = 0.0;
      for (int k = 0; k < m; ++k)
        if (judged(k) && static_cast<int>(kind[k]) == c) s_max = std::max(s_max, s0[k]);
      kernels[c].mu = kernels[c].initialMu(s_max);
    }
    kernels[0].mu = 1.0;
    RobustKernel& tls = kernels[static_cast<int>(KernelKind::kTruncatedLeastSquares)];
    const RobustKernel& gm = kernels[static_cast<int>(KernelKind::kGemanMcClure)];
    auto kernelOf = [&](int k) -> const RobustKernel& {
      return kernels[static_cast<int>(kind[k])];
    };

    result.converged = false;
    bool done = result.cancelled;
    if (!done && all_tls) {
      // x⁰ with every weighted s_k(x⁰) ≤ c² is a local minimum of Σ min(s_k, c²) (there TLS is
      // least squares, and x⁰ minimises it): TLS's answer, whatever μ⁰ says; GTSAM stops likewise
      // when s_max ≤ c²/2 at its initial values.
      double s_max_ls = 0.0;
      for (int k = 0; k < m; ++k)
        if (judged(k)) s_max_ls = std::max(s_max_ls, s[k]);
      if (std::isinf(tls.mu) || s_max_ls <= result.threshold) {
        result.converged = done = true;
        result.message = "every residual within c² at the least-squares start";
      }
    }
    tls.mu = std::max(tls.mu, options.min_initial_mu);
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
      bool binary = true;   // every TLS weight within tolerance of 0 or 1
      double change = 0.0;  // the largest move of a reweighted (Huber, Cauchy) weight
      for (int k = 0; k < m; ++k) {
        if (!judged(k)) continue;
        const RobustKernel& kernel = kernelOf(k);
        w[k] = kernel.weight(s[k]);
        if (kernel.kind == KernelKind::kTruncatedLeastSquares &&
            std::min(w[k], 1.0 - w[k]) > options.weight_tolerance)
          binary = false;
        if (!kernel.isGraduated()) change = std::max(change, std::abs(w[k] - previous[k]));
      }
      if (!any_graduated && change <= options.weight_tolerance) {
        result.converged = true;
        result.message = "weights converged";
        break;
      }
      previous = w;
      const std::vector<G> finished = *poses;  // the last step's estimate, kept if cancelled
      if (restart && any_graduated) *poses = x_init;
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
        for (int k = 0; k < m; ++k) out += !result.trusted[k] && w[k] < kernelOf(k).inlierCut();
        std::fprintf(stderr,
                     "gnc step %3d  c² %.4g  μ tls %.4g gm %.4g  weighted F %.10e  outliers %d  "
                     "max Δw %.3g  inner %d (%s)\n",
                     it, result.threshold, tls.mu, gm.mu, cost, out, change, step.iterations,
                     toString(step.termination).c_str());
      }
      if (!any_graduated) continue;
      // GTSAM's checkConvergence, on the weights this step solved with and its cost: every kind
      // at its kernel (TLS binary, GM at μ = 1, the reweighted ones still), or the cost still.
      const bool irls_still = change <= options.weight_tolerance;
      if (binary && gm.atKernel() && irls_still) {
        result.converged = true;
        result.message = all_tls ? "weights binary" : "every kernel reached";
        break;
      }
      if (std::abs(cost - previous_cost) / std::max(previous_cost, 1e-7) < options.cost_tolerance) {
        result.converged = true;
        result.message = "weighted cost converged";
        break;
      }
      previous_cost = cost;
      for (RobustKernel& kernel : kernels)
        if (kernel.isGraduated()) kernel.mu = kernel.nextMu(options.mu_factor);
    }
    if (!result.converged && !result.cancelled) result.message = "GNC iteration limit reached";
    if (result.converged && done)
      for (int k = 0; k < m; ++k) w[k] = fixed_out[k] ? 0.0 : 1.0;
    for (int k = 0; k < m; ++k)
      inlier[k] = result.trusted[k] || (!fixed_out[k] && w[k] >= kernelOf(k).inlierCut());
    result.mu = any_graduated ? (all_tls ? tls.mu : gm.mu) : 1.0;
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
  auto kernelOf = [&](int k) -> const RobustKernel& { return kernels[static_cast<int>(kind[k])]; };

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
    if (!result.trusted[k]) result.robust_cost += kernelOf(k).rho(s[k]) - (inlier[k] ? s[k] : 0.0);
  }
  result.time_s = std::chrono::duration<double>(Clock::now() - start).count();
  return result;
}

template <class G>
CertifiedInliers certifyInliers(const PoseGraph<G>& graph, GncResult* gnc, std::vector<G>* poses,
                                const RtrOptions& options, int max_passes, double take_back) {
  if (!(take_back >= 0) || !std::isfinite(take_back))
    throw std::invalid_argument(
        "certifyInliers: the take-back threshold must be finite and >= 0, "
        "got " +
        std::to_string(take_back));
  const double bound = take_back > 0 ? take_back : gnc->threshold;
  CertifiedInliers out;
  for (int pass = 0; pass < max_passes; ++pass) {
    const PoseGraph<G> inliers = keepEdges(graph, gnc->inlier);
    out.rtr = solveRtr(inliers, poses, options);
    ++out.passes;
    const int taken = takeBackFitting(edgeCosts(graph, *poses), bound, gnc);
    out.readmitted += taken;
    if (taken == 0) break;
  }
  recountClassification(graph, *poses, gnc);
  return out;
}

template <class G>
int readmitFitting(const PoseGraph<G>& graph, GncResult* gnc, std::vector<G>* poses,
                   double threshold, const BatchOptions& options, int max_passes) {
  const int m = graph.numEdges();
  if (static_cast<int>(gnc->inlier.size()) != m || static_cast<int>(gnc->weights.size()) != m)
    throw std::invalid_argument("readmitFitting: a classification of " +
                                std::to_string(gnc->inlier.size()) + " edges for a graph of " +
                                std::to_string(m));
  if (!(threshold >= 0) || !std::isfinite(threshold))
    throw std::invalid_argument("readmitFitting: the threshold must be finite and >= 0, got " +
                                std::to_string(threshold));
  WeightedBatchSolver<G> solver(graph);
  int readmitted = 0;
  for (int pass = 0; pass < max_passes; ++pass) {
    const int taken = takeBackFitting(edgeCosts(graph, *poses), threshold, gnc);
    if (taken == 0) break;
    readmitted += taken;
    gnc->lm_iterations += solver.solve(inlierWeights(*gnc), poses, options).iterations;
  }
  recountClassification(graph, *poses, gnc);
  return readmitted;
}

template GncResult solveGnc(const PoseGraph<SE2>&, std::vector<SE2>*, const GncOptions&);
template GncResult solveGnc(const PoseGraph<SE3>&, std::vector<SE3>*, const GncOptions&);
template CertifiedInliers certifyInliers(const PoseGraph<SE2>&, GncResult*, std::vector<SE2>*,
                                         const RtrOptions&, int, double);
template CertifiedInliers certifyInliers(const PoseGraph<SE3>&, GncResult*, std::vector<SE3>*,
                                         const RtrOptions&, int, double);
template int readmitFitting(const PoseGraph<SE2>&, GncResult*, std::vector<SE2>*, double,
                            const BatchOptions&, int);
template int readmitFitting(const PoseGraph<SE3>&, GncResult*, std::vector<SE3>*, double,
                            const BatchOptions&, int);
template bool trustedEdge(const PoseGraph<SE2>&, const GncOptions&, int);
template bool trustedEdge(const PoseGraph<SE3>&, const GncOptions&, int);
template PoseGraph<SE2> keepEdges(const PoseGraph<SE2>&, const std::vector<char>&);
template PoseGraph<SE3> keepEdges(const PoseGraph<SE3>&, const std::vector<char>&);

}  // namespace arbor
