#include "arbor_slam/core/batch_solver.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <limits>
#include <memory>
#include <stdexcept>

#include "arbor_slam/core/normal_equations.h"

namespace arbor {
namespace {

using Clock = std::chrono::steady_clock;

constexpr double kMinDiagonal = 1e-6;     // LM/dogleg scaling diag(H) clamped to
constexpr double kMaxDiagonal = 1e32;     //   [kMinDiagonal, kMaxDiagonal] (as Ceres)
constexpr double kMinRadius = 1e-32;      // trust region collapsed below this: diverged
constexpr double kMaxRadius = 1e16;       // trust region never grows past this
constexpr double kMinStepQuality = 1e-3;  // accept a step when ρ exceeds this
constexpr double kStepTolerance = 1e-8;   // ‖δ‖ ≤ tol·(‖x‖ + tol): converged (as Ceres)
constexpr double kGradientTolerance = 1e-10;  // max |g| below this: converged
constexpr int kMaxFactorizationFailures = 10;

bool isFinite(const Eigen::VectorXd& v) { return v.allFinite(); }

// State shared by the three methods: the estimate, its cost and linearisation, the summary.
template <class G>
class Minimizer {
 public:
  // `equations` are the graph's, with its edge weights set or not (then F is the plain one).
  Minimizer(const PoseGraph<G>& graph, NormalEquations<G>& equations, std::vector<G>* poses,
            const BatchOptions& options, BatchSummary* summary, Clock::time_point start)
      : graph_(graph),
        poses_(*poses),
        options_(options),
        summary_(*summary),
        start_(start),
        equations_(equations) {
    double norm2 = 0.0;
    for (const G& x : poses_) norm2 += x.translation().squaredNorm() + 1.0;
    parameter_norm_ = std::sqrt(norm2);
  }

  // Linearises at the start; false if nothing is left to do.
  bool start() {
    F_ = equations_.linearize(poses_);
    summary_.F_initial = summary_.F_final = F_;
    if (!std::isfinite(F_)) return diverge("the initial objective is not finite");
    if (options_.verbose)
      std::fprintf(stderr,
                   "%s: %d poses, %d unknowns, nnz(H) %.0f, nnz(L) %.0f, %.3g flops/factorisation "
                   "(%s), F0 %.10e\n",
                   toString(options_.method).c_str(), graph_.numPoses(), equations_.dimension(),
                   equations_.hessianNonzeros(), equations_.factorNonzeros(),
                   equations_.factorizationFlops(),
                   equations_.backend() == CholeskyBackend::kBlock ? "block" : "CHOLMOD", F_);
    if (converged()) return false;
    return true;
  }

  // Plain Gauss–Newton: H δ = −g, x ← x ⊞ δ (non-monotone; the best point seen is returned).
  void gaussNewton() {
    Eigen::VectorXd delta;
    Best best{{}, F_, true};
    while (summary_.iterations < options_.max_iterations) {
      if (cancelled()) {
        restore(best);
        summary_.F_final = F_;
        return;
      }
      ++summary_.iterations;
      if (!equations_.factorize()) {
        restore(best);
        diverge(equations_.factorizationFailure());
        return;
      }
      equations_.solve(-equations_.gradient(), &delta);
      equations_.retract(poses_, delta, &trial_);
      const double F_new =
          isFinite(delta) ? cost(trial_) : std::numeric_limits<double>::quiet_NaN();
      log("gn", F_new, 1.0, 0.0, delta.norm(), true);
      if (!std::isfinite(F_new) || F_new > 10.0 * best.F) {
        restore(best);
        diverge("Gauss-Newton diverged: a step took F from " + std::to_string(F_) + " to " +
                std::to_string(F_new));
        return;
      }
      const bool small =
          std::abs((F_ - F_new) / F_) < options_.relative_tolerance || tinyStep(delta);
      if (F_new <= F_ || !small) {  // a small increase is roundoff at the minimum: not taken
        if (F_new <= best.F) {
          best.current = true;
        } else if (best.current) {  // leaving the best point: keep a copy
          best.poses = poses_;
          best.current = false;
        }
        poses_.swap(trial_);
        F_ = F_new;
      }
      if (small) {
        restore(best);
        finish(Termination::kConverged, "relative change below tolerance");
        return;
      }
      F_ = equations_.linearize(poses_);
      if (best.current) best.F = F_;
      if (converged()) return;
    }
    restore(best);
    finish(Termination::kMaxIterations, "iteration limit reached");
  }

  // Ceres' LevenbergMarquardtStrategy: (H + D/radius) δ = −g, D = diag(H) clamped.
  void levenbergMarquardt() {
    double radius = 1e4, decrease_factor = 2.0;
    int failures = 0;
    Eigen::VectorXd damping, delta;
    while (summary_.iterations < options_.max_iterations) {
      if (cancelled()) return;
      ++summary_.iterations;
      damping = equations_.hessianDiagonal().cwiseMax(kMinDiagonal).cwiseMin(kMaxDiagonal) / radius;
      bool valid = equations_.factorize(&damping);
      if (valid) {
        equations_.solve(-equations_.gradient(), &delta);
        valid = isFinite(delta);
      } else if (++failures >= kMaxFactorizationFailures) {
        diverge(equations_.factorizationFailure());
        return;
      }
      if (valid) {
        failures = 0;
        const Step step = evaluate(delta);
        log("lm", step.F_new, step.rho, radius, delta.norm(), step.accepted);
        if (step.accepted) {
          const double r = 2.0 * step.rho - 1.0;
          radius = std::min(kMaxRadius, radius / std::max(1.0 / 3.0, 1.0 - r * r * r));
          decrease_factor = 2.0;
          if (accept(step)) return;
          continue;
        }
        if (step.tiny) {
          finish(Termination::kConverged, "step below parameter tolerance");
          return;
        }
      }
      radius /= decrease_factor;
      decrease_factor *= 2.0;
      if (radius < kMinRadius) {
        diverge("trust region radius collapsed below 1e-32 without a successful step");
        return;
      }
    }
    finish(Termination::kMaxIterations, "iteration limit reached");
  }

  // Powell's dogleg in Ceres' scaled variables y = Dδ, D = sqrt(diag(H)) clamped; radius
  // updates after Nocedal & Wright, Numerical Optimization (2006), Alg. 4.1.
  void dogleg(double initial_radius) {
    double radius = initial_radius;
    Eigen::VectorXd scale, gauss_newton, cauchy, scaled_gradient, y, delta;
    bool linearized = true;
    while (summary_.iterations < options_.max_iterations) {
      if (cancelled()) return;
      ++summary_.iterations;
      if (linearized) {
        scale =
            equations_.hessianDiagonal().cwiseMax(kMinDiagonal).cwiseMin(kMaxDiagonal).cwiseSqrt();
        if (!gaussNewtonStep(&gauss_newton)) return;
        gauss_newton = gauss_newton.cwiseProduct(scale);
        scaled_gradient = equations_.gradient().cwiseQuotient(scale);
        // Cauchy point: α = g̃ᵀg̃ / g̃ᵀH̃g̃ with H̃ = D⁻¹HD⁻¹, i.e. ‖A D⁻¹g̃‖² below.
        const double gg = scaled_gradient.squaredNorm();
        const double gHg = equations_.jacobianSquaredNorm(scaled_gradient.cwiseQuotient(scale));
        cauchy = -(gHg > 0 ? gg / gHg : 0.0) * scaled_gradient;
        linearized = false;
      }
      const double gn_norm = gauss_newton.norm(), cauchy_norm = cauchy.norm();
      if (gn_norm <= radius) {
        y = gauss_newton;
      } else if (cauchy_norm >= radius) {
        y = (radius / cauchy_norm) * cauchy;
      } else {  // ‖cauchy + β (gn − cauchy)‖ = radius, β ∈ [0, 1]
        const Eigen::VectorXd d = gauss_newton - cauchy;
        const double a = d.squaredNorm(), b = cauchy.dot(d);
        const double c = cauchy_norm * cauchy_norm - radius * radius;
        const double disc = std::sqrt(std::max(0.0, b * b - a * c));
        const double beta = b <= 0 ? (disc - b) / a : -c / (b + disc);
        y = cauchy + beta * d;
      }
      delta = y.cwiseQuotient(scale);
      const double step_norm = y.norm();
      const Step step = evaluate(delta);
      log("dogleg", step.F_new, step.rho, radius, step_norm, step.accepted);
      if (step.rho < 0.25 || !step.accepted)
        radius = 0.25 * std::min(radius, step_norm);
      else if (step.rho > 0.75 && step_norm >= 0.99 * radius)
        radius = std::min(kMaxRadius, 2.0 * radius);
      if (step.accepted) {
        if (accept(step)) return;
        linearized = true;
        continue;
      }
      if (step.tiny) {
        finish(Termination::kConverged, "step below parameter tolerance");
        return;
      }
      if (radius < kMinRadius) {
        diverge("trust region radius collapsed below 1e-32 without a successful step");
        return;
      }
    }
    finish(Termination::kMaxIterations, "iteration limit reached");
  }

  void finish(Termination termination, const std::string& message) {
    summary_.termination = termination;
    summary_.message = message;
    summary_.F_final = F_;
  }

  bool diverge(const std::string& message) {
    finish(Termination::kDiverged, message);
    return false;
  }

 private:
  // The token's check before an iteration; when cancelled the summary says so (LM and dogleg
  // hold the best point at every iteration start, Gauss–Newton restores its best first).
  bool cancelled() {
    if (!options_.cancel.cancelled()) return false;
    finish(Termination::kCancelled,
           "cancelled after " + std::to_string(summary_.iterations) + " iterations");
    return true;
  }

  struct Step {
    double F_new = 0, rho = 0;
    bool accepted = false, tiny = false;
  };

  // The trial point poses ⊞ δ, its cost and gain ratio ρ = actual / model decrease.
  Step evaluate(const Eigen::VectorXd& delta) {
    Step s;
    s.tiny = tinyStep(delta);
    const double model_decrease = F_ - equations_.modelCost(delta);
    equations_.retract(poses_, delta, &trial_);
    s.F_new = cost(trial_);
    s.rho = (F_ - s.F_new) / model_decrease;
    s.accepted = std::isfinite(s.F_new) &&
                 ((model_decrease > 0 && s.rho > kMinStepQuality) || (s.tiny && s.F_new <= F_));
    return s;
  }

  // Moves to the trial point; true when converged (then not relinearised).
  bool accept(const Step& step) {
    const double relative_decrease = (F_ - step.F_new) / F_;
    poses_.swap(trial_);
    F_ = step.F_new;
    if (step.tiny || relative_decrease < options_.relative_tolerance) {
      finish(Termination::kConverged,
             step.tiny ? "step below parameter tolerance" : "relative decrease below tolerance");
      return true;
    }
    F_ = equations_.linearize(poses_);
    return converged();
  }

  // Converged at the current linearisation point (zero objective or gradient)?
  bool converged() {
    if (equations_.dimension() == 0) {
      finish(Termination::kConverged, "no free poses");
    } else if (F_ == 0.0) {
      finish(Termination::kConverged, "zero objective");
    } else if (equations_.gradient().cwiseAbs().maxCoeff() <= kGradientTolerance) {
      finish(Termination::kConverged, "gradient below tolerance");
    } else {
      return false;
    }
    return true;
  }

  bool tinyStep(const Eigen::VectorXd& delta) const {
    return delta.norm() <= kStepTolerance * (parameter_norm_ + kStepTolerance);
  }

  // The Gauss–Newton step for dogleg, damped by μ·diag(H) (μ = 1e-8 … 1e-2) if H is singular.
  bool gaussNewtonStep(Eigen::VectorXd* step) {
    if (!equations_.factorize()) {
      const Eigen::VectorXd diagonal =
          equations_.hessianDiagonal().cwiseMax(kMinDiagonal).cwiseMin(kMaxDiagonal);
      bool ok = false;
      double mu = 1e-8;
      for (int attempt = 0; !ok && attempt < 7; ++attempt, mu *= 10) {
        const Eigen::VectorXd damping = mu * diagonal;
        ok = equations_.factorize(&damping);
      }
      if (!ok) return diverge(equations_.factorizationFailure());
    }
    equations_.solve(-equations_.gradient(), step);
    if (!isFinite(*step)) return diverge("the Gauss-Newton step is not finite");
    return true;
  }

  // The best point Gauss–Newton has seen: the current one, or a saved copy.
  struct Best {
    std::vector<G> poses;
    double F = 0;
    bool current = true;
  };
  void restore(const Best& best) {
    if (best.current) return;
    poses_ = best.poses;
    F_ = best.F;
  }

  void log(const char* method, double F_new, double rho, double radius, double step_norm,
           bool accepted) const {
    if (!options_.verbose) return;
    const double seconds = std::chrono::duration<double>(Clock::now() - start_).count();
    std::fprintf(stderr,
                 "%s %4d  F %.10e  F_new %.10e  rho %9.3e  radius %9.3e  |step| %9.3e  %s  "
                 "%.3f s\n",
                 method, summary_.iterations, F_, F_new, rho, radius, step_norm,
                 accepted ? "accepted" : "rejected", seconds);
  }

  // The objective the equations linearise: F, or Σ w eᵀΩe over the edges with weights set.
  double cost(const std::vector<G>& poses) const {
    const std::vector<double>* w = equations_.edgeWeights();
    return w ? weightedObjective(graph_, *w, poses) : objective(graph_, poses);
  }

  const PoseGraph<G>& graph_;
  std::vector<G>& poses_;
  const BatchOptions& options_;
  BatchSummary& summary_;
  Clock::time_point start_;
  NormalEquations<G>& equations_;
  std::vector<G> trial_;
  double F_ = 0.0;
  double parameter_norm_ = 0.0;
};

void checkOptions(const BatchOptions& options) {
  if (options.max_iterations < 0)
    throw std::invalid_argument("BatchOptions.max_iterations must be >= 0, got " +
                                std::to_string(options.max_iterations));
  if (!(options.relative_tolerance >= 0) || !std::isfinite(options.relative_tolerance))
    throw std::invalid_argument("BatchOptions.relative_tolerance must be finite and >= 0, got " +
                                std::to_string(options.relative_tolerance));
}

}  // namespace

std::string toString(BatchMethod method) {
  switch (method) {
    case BatchMethod::kGaussNewton:
      return "gn";
    case BatchMethod::kLevenbergMarquardt:
      return "lm";
    case BatchMethod::kDogleg:
      return "dogleg";
  }
  return "unknown";
}

std::string toString(Termination termination) {
  switch (termination) {
    case Termination::kConverged:
      return "converged";
    case Termination::kMaxIterations:
      return "max_iterations";
    case Termination::kDiverged:
      return "diverged";
    case Termination::kCancelled:
      return "cancelled";
  }
  return "unknown";
}

BatchMethod parseBatchMethod(const std::string& name) {
  for (BatchMethod m :
       {BatchMethod::kGaussNewton, BatchMethod::kLevenbergMarquardt, BatchMethod::kDogleg})
    if (name == toString(m)) return m;
  throw std::invalid_argument("unknown batch method '" + name + "' (expected gn, lm or dogleg)");
}

namespace {

// solveBatch and WeightedBatchSolver::solve: `equations` null makes the graph's own (unweighted).
template <class G>
BatchSummary minimize(const PoseGraph<G>& graph, NormalEquations<G>* equations,
                      std::vector<G>* poses, const BatchOptions& options, const char* caller) {
  const Clock::time_point start = Clock::now();
  checkOptions(options);
  if (!poses) throw std::invalid_argument(std::string(caller) + ": null pose vector");
  if (static_cast<int>(poses->size()) != graph.numPoses())
    throw std::invalid_argument(std::string(caller) + ": " + std::to_string(poses->size()) +
                                " poses for a graph of " + std::to_string(graph.numPoses()));
  BatchSummary summary;
  const std::string problem = gaugeProblem(graph);
  if (!problem.empty()) {
    const std::vector<double>* w = equations ? equations->edgeWeights() : nullptr;
    summary.F_initial = summary.F_final =
        w ? weightedObjective(graph, *w, *poses) : objective(graph, *poses);
    summary.termination = Termination::kDiverged;
    summary.message = problem;
  } else {
    std::unique_ptr<NormalEquations<G>> own;
    if (!equations) {
      own = std::make_unique<NormalEquations<G>>(graph);
      equations = own.get();
    }
    Minimizer<G> minimizer(graph, *equations, poses, options, &summary, start);
    if (minimizer.start()) {
      switch (options.method) {
        case BatchMethod::kGaussNewton:
          minimizer.gaussNewton();
          break;
        case BatchMethod::kLevenbergMarquardt:
          minimizer.levenbergMarquardt();
          break;
        case BatchMethod::kDogleg:
          minimizer.dogleg(1.0);
          break;
      }
    }
  }
  summary.time_s = std::chrono::duration<double>(Clock::now() - start).count();
  if (options.verbose)
    std::fprintf(stderr, "%s: %s after %d iterations, F %.10e -> %.10e, %.3f s%s%s\n",
                 toString(options.method).c_str(), toString(summary.termination).c_str(),
                 summary.iterations, summary.F_initial, summary.F_final, summary.time_s,
                 summary.message.empty() ? "" : ": ", summary.message.c_str());
  return summary;
}

}  // namespace

template <class G>
BatchSummary solveBatch(const PoseGraph<G>& graph, std::vector<G>* poses,
                        const BatchOptions& options) {
  return minimize<G>(graph, nullptr, poses, options, "solveBatch");
}

template <class G>
WeightedBatchSolver<G>::WeightedBatchSolver(const PoseGraph<G>& graph)
    : graph_(graph), equations_(std::make_unique<NormalEquations<G>>(graph)) {}

template <class G>
WeightedBatchSolver<G>::~WeightedBatchSolver() = default;

template <class G>
BatchSummary WeightedBatchSolver<G>::solve(const std::vector<double>& edge_weights,
                                           std::vector<G>* poses, const BatchOptions& options) {
  for (size_t k = 0; k < edge_weights.size(); ++k)
    if (!(edge_weights[k] >= 0.0) || !std::isfinite(edge_weights[k]))
      throw std::invalid_argument("WeightedBatchSolver: weight of edge " + std::to_string(k) +
                                  " must be finite and >= 0, got " +
                                  std::to_string(edge_weights[k]));
  equations_->setEdgeWeights(&edge_weights);  // checks the size
  BatchSummary summary =
      minimize<G>(graph_, equations_.get(), poses, options, "WeightedBatchSolver");
  equations_->setEdgeWeights(nullptr);
  return summary;
}

template <class G>
std::vector<typename G::Tangent> gaussNewtonStep(const PoseGraph<G>& graph,
                                                 const std::vector<G>& poses) {
  if (static_cast<int>(poses.size()) != graph.numPoses())
    throw std::invalid_argument("gaussNewtonStep: " + std::to_string(poses.size()) +
                                " poses for a graph of " + std::to_string(graph.numPoses()));
  const std::string problem = gaugeProblem(graph);
  if (!problem.empty()) throw std::runtime_error("gaussNewtonStep: " + problem);
  NormalEquations<G> equations(graph);
  equations.linearize(poses);
  if (!equations.factorize())
    throw std::runtime_error("gaussNewtonStep: " + equations.factorizationFailure());
  Eigen::VectorXd delta;
  equations.solve(-equations.gradient(), &delta);
  return equations.perPose(delta);
}

template class WeightedBatchSolver<SE2>;
template class WeightedBatchSolver<SE3>;
template BatchSummary solveBatch(const PoseGraph<SE2>&, std::vector<SE2>*, const BatchOptions&);
template BatchSummary solveBatch(const PoseGraph<SE3>&, std::vector<SE3>*, const BatchOptions&);
template std::vector<SE2::Tangent> gaussNewtonStep(const PoseGraph<SE2>&, const std::vector<SE2>&);
template std::vector<SE3::Tangent> gaussNewtonStep(const PoseGraph<SE3>&, const std::vector<SE3>&);

}  // namespace arbor
