#include "arbor_slam/core/riemannian_staircase.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <iostream>
#include <limits>
#include <stdexcept>

#include <Spectra/SymEigsSolver.h>
#include <Eigen/Eigenvalues>

#include "arbor_slam/core/elapsed.h"
#include "arbor_slam/core/initialization.h"
#include "arbor_slam/core/serial_openmp.h"
#include "arbor_slam/core/stiefel_product.h"

namespace arbor {

namespace {

using Clock = std::chrono::steady_clock;

double inner(const Eigen::MatrixXd& A, const Eigen::MatrixXd& B) { return A.cwiseProduct(B).sum(); }

// f, Q X, the Riemannian gradient and Λ at one point of St(d, r)ⁿ.
struct PointData {
  Eigen::MatrixXd X, QX, grad, lambda;
  double f = 0;
};

PointData evaluate(const SESyncProblem& problem, Eigen::MatrixXd X) {
  const int d = problem.dim();
  PointData p;
  p.X = std::move(X);
  p.QX = problem.Q(p.X);
  p.f = inner(p.X, p.QX);
  p.grad = stiefel::project(p.X, 2.0 * p.QX, d);
  p.lambda = problem.lambdaBlocks(p.X, p.QX);
  return p;
}

// Riemannian Hessian of f(X) = tr(XᵀQX) along V: Proj_X(2 Q V − 2 Λ V) (SE-Sync eq. 111).
Eigen::MatrixXd hessian(const SESyncProblem& problem, const PointData& p,
                        const Eigen::MatrixXd& V) {
  const int d = problem.dim();
  Eigen::MatrixXd H = problem.Q(V);
  H -= stiefel::blockMultiply(p.lambda, V, d);
  return stiefel::project(p.X, 2.0 * H, d);
}

Eigen::MatrixXd precondition(const SESyncProblem& problem, const PointData& p,
                             const Eigen::MatrixXd& V) {
  return stiefel::project(p.X, problem.precondition(V), problem.dim());
}

struct TcgResult {
  Eigen::MatrixXd eta, Heta;
  int iterations = 0;
  bool boundary = false;
};

// Steihaug–Toint truncated preconditioned CG for the trust-region subproblem
// min ⟨g, η⟩ + ½⟨η, H η⟩ s.t. ‖η‖_{P⁻¹} ≤ Δ (Absil, Baker, Gallivan 2007, Algorithm 2).
TcgResult truncatedCG(const SESyncProblem& problem, const PointData& p, const Eigen::MatrixXd& z0,
                      double delta, const RtrOptions& options) {
  TcgResult out;
  out.eta = Eigen::MatrixXd::Zero(p.X.rows(), p.X.cols());
  out.Heta = out.eta;
  Eigen::MatrixXd r = p.grad;
  Eigen::MatrixXd z = z0;
  double z_r = inner(z, r);
  double d_Pd = z_r, e_Pd = 0, e_Pe = 0;
  const double r0 = std::sqrt(inner(r, r));
  const double target = r0 * std::min(std::pow(r0, options.tcg_theta), options.tcg_kappa);
  Eigen::MatrixXd dir = -z;
  const double delta2 = delta * delta;
  for (int k = 0; k < options.max_tcg_iterations; ++k) {
    if (k > 0 && options.cancel.cancelled()) return out;  // η so far: inside the region
    const Eigen::MatrixXd Hd = hessian(problem, p, dir);
    const double d_Hd = inner(dir, Hd);
    out.iterations = k + 1;
    const double alpha = z_r / d_Hd;
    const double e_Pe_new = e_Pe + 2 * alpha * e_Pd + alpha * alpha * d_Pd;
    if (!(d_Hd > 0) || e_Pe_new >= delta2) {
      // Negative curvature or the boundary: go to the trust-region boundary along dir.
      const double tau = (-e_Pd + std::sqrt(e_Pd * e_Pd + d_Pd * (delta2 - e_Pe))) / d_Pd;
      out.eta += tau * dir;
      out.Heta += tau * Hd;
      out.boundary = true;
      return out;
    }
    e_Pe = e_Pe_new;
    out.eta += alpha * dir;
    out.Heta += alpha * Hd;
    r += alpha * Hd;
    if (std::sqrt(inner(r, r)) <= target) return out;
    z = precondition(problem, p, r);
    const double z_r_old = z_r;
    z_r = inner(z, r);
    const double beta = z_r / z_r_old;
    dir = -z + beta * dir;
    e_Pd = beta * (e_Pd + alpha * d_Pd);
    d_Pd = z_r + beta * beta * d_Pd;
  }
  return out;
}

struct LevelResult {
  PointData point;
  int iterations = 0, tcg_iterations = 0;
  std::string stop;
  double radius = 0;  // the final trust-region radius
};

// Riemannian trust region on St(d, r)ⁿ (Absil, Baker, Gallivan 2007, Algorithm 1).
LevelResult riemannianTrustRegion(const SESyncProblem& problem, PointData p,
                                  const RtrOptions& options, double initial_radius) {
  LevelResult out;
  double delta = initial_radius;  // ≤ 0: set from the first preconditioned gradient
  double delta_max = 1e6 * initial_radius;
  double gnorm = std::sqrt(inner(p.grad, p.grad));
  for (int it = 0; it < options.max_iterations; ++it) {
    if (options.cancel.cancelled()) {
      out.stop = "cancelled";
      break;
    }
    if (gnorm < options.gradient_tolerance) {
      out.stop = "gradient";
      break;
    }
    const Eigen::MatrixXd z0 = precondition(problem, p, p.grad);
    const double pgnorm = std::sqrt(inner(z0, z0));
    if (pgnorm < options.preconditioned_gradient_tolerance) {
      out.stop = "preconditioned gradient";
      break;
    }
    if (delta <= 0) {
      // ‖P g‖_{P⁻¹}: the length of a full (preconditioned) Newton step in the trust-region norm.
      delta = std::sqrt(std::max(inner(z0, p.grad), 1e-300));
      delta_max = 1e6 * delta;
    }
    TcgResult step = truncatedCG(problem, p, z0, delta, options);
    out.iterations++;
    out.tcg_iterations += step.iterations;
    PointData next = evaluate(problem, stiefel::retract(p.X, step.eta, problem.dim()));
    const double model_decrease = -(inner(p.grad, step.eta) + 0.5 * inner(step.eta, step.Heta));
    const double actual = p.f - next.f;
    const double rho = model_decrease > 0 ? actual / model_decrease : -1.0;
    if (rho < 0.25) {
      delta /= 4;
    } else if (rho > 0.75 && step.boundary) {
      delta = std::min(2 * delta, delta_max);
    }
    if (options.verbose) {
      std::cerr << "  rtr it " << it << " f " << p.f << " |g| " << gnorm << " |Pg| " << pgnorm
                << " tCG " << step.iterations << (step.boundary ? " (boundary)" : "") << " rho "
                << rho << " delta " << delta << "\n";
    }
    if (rho > 0.1 && actual > 0) {
      const double rel = actual / std::max(std::abs(p.f), 1e-300);
      const double step_norm = std::sqrt(inner(step.eta, step.eta));
      p = std::move(next);
      gnorm = std::sqrt(inner(p.grad, p.grad));
      if (rel < options.relative_decrease_tolerance) {
        out.stop = "relative decrease";
        break;
      }
      if (step_norm < options.step_tolerance) {
        out.stop = "step size";
        break;
      }
    } else if (delta < 1e-12 * delta_max) {
      out.stop = "trust region collapsed";
      break;
    }
    if (it + 1 == options.max_iterations) out.stop = "max iterations";
  }
  if (out.stop.empty()) out.stop = "max iterations";
  out.point = std::move(p);
  out.radius = delta;
  return out;
}

// x ↦ (Q − Λ − σI) x for Spectra.
struct CertificateOp {
  using Scalar = double;
  const SESyncProblem* problem;
  const Eigen::MatrixXd* lambda;
  double shift = 0;
  Eigen::Index n;
  Eigen::Index rows() const { return n; }
  Eigen::Index cols() const { return n; }
  void perform_op(const double* x, double* y) const {
    const Eigen::Map<const Eigen::VectorXd> xv(x, n);
    Eigen::Map<Eigen::VectorXd>(y, n) = problem->certificateProduct(*lambda, xv) - shift * xv;
  }
};

// Escape a saddle at rank r along the negative-curvature direction v, lifting to rank r + 1
// (SE-Sync §4.1.2): Y₊ = R(Y ⊕ 0, α [0 v]) for the largest α tried (√n, halving) that lowers f,
// preferring one whose gradient is above tolerance (SE-Sync's condition); a weak saddle may only
// offer points with a smaller gradient, which the next level then has to go below.
bool escapeSaddle(const SESyncProblem& problem, const PointData& p, const Eigen::VectorXd& v,
                  const RtrOptions& options, PointData* out) {
  const int d = problem.dim();
  const Eigen::Index r = p.X.cols();
  Eigen::MatrixXd X = Eigen::MatrixXd::Zero(p.X.rows(), r + 1);
  X.leftCols(r) = p.X;
  Eigen::MatrixXd V = Eigen::MatrixXd::Zero(p.X.rows(), r + 1);
  V.col(r) = v.normalized();
  double alpha = std::sqrt(static_cast<double>(problem.numPoses()));
  bool found = false;
  for (int k = 0; k < 60; ++k, alpha /= 2) {
    PointData q = evaluate(problem, stiefel::retract(X, alpha * V, d));
    if (!(q.f < p.f)) continue;
    const bool strong = std::sqrt(inner(q.grad, q.grad)) > options.gradient_tolerance;
    if (!found || strong) {
      *out = std::move(q);
      found = true;
    }
    if (strong) break;
  }
  return found;
}

Eigen::MatrixXd roundToRotations(const Eigen::MatrixXd& X, int d) {
  // Rank-d truncated SVD of Y = Xᵀ through the r×r Gram matrix XᵀX (SE-Sync Algorithm 3).
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(X.transpose() * X);
  const Eigen::MatrixXd U = eig.eigenvectors().rightCols(d).rowwise().reverse();
  Eigen::MatrixXd R = X * U;  // block i ≈ Rᵢᵀ, up to a common reflection
  const Eigen::Index n = X.rows() / d;
  Eigen::Index positive = 0;
  for (Eigen::Index i = 0; i < n; ++i) {
    if (R.middleRows(d * i, d).determinant() > 0) ++positive;
  }
  if (positive < n - positive) R.col(d - 1) *= -1.0;
  for (Eigen::Index i = 0; i < n; ++i) {
    R.middleRows(d * i, d) = stiefel::projectToSO(R.middleRows(d * i, d));
  }
  return R;
}

SE2 makePose(const Eigen::Matrix2d& R, const Eigen::Vector2d& t, SE2*) {
  return SE2(t, std::atan2(R(1, 0), R(0, 0)));
}
SE3 makePose(const Eigen::Matrix3d& R, const Eigen::Vector3d& t, SE3*) {
  return SE3(Eigen::Quaterniond(R).normalized(), t);
}

template <class G>
Eigen::MatrixXd rotationBlocks(const std::vector<G>& poses) {
  constexpr int d = G::kDim;
  Eigen::MatrixXd X(d * poses.size(), d);
  for (std::size_t i = 0; i < poses.size(); ++i) {
    X.middleRows(d * i, d) = poses[i].rotation().transpose();
  }
  return X;
}

}  // namespace

MinimumEigenpair certificateMinimumEigenpair(const SESyncProblem& problem,
                                             const Eigen::MatrixXd& X) {
  const int d = problem.dim();
  if (X.rows() != d * problem.numPoses() || X.cols() < d) {
    throw std::invalid_argument("certificateMinimumEigenpair: X must be dn × r with r ≥ d");
  }
  const SerialOpenMP serial;
  const Eigen::MatrixXd lambda = problem.lambdaBlocks(X, problem.Q(X));
  const Eigen::Index n = X.rows();
  const Eigen::Index ncv = std::min<Eigen::Index>(30, n);
  MinimumEigenpair out;
  CertificateOp op{&problem, &lambda, 0.0, n};
  double lambda_lm = 0;
  {
    Spectra::SymEigsSolver<CertificateOp> eigs(op, 1, ncv);
    eigs.init();
    eigs.compute(Spectra::SortRule::LargestMagn, 1000, 1e-4);
    if (eigs.info() != Spectra::CompInfo::Successful) {
      throw std::runtime_error("certificateMinimumEigenpair: Lanczos did not converge");
    }
    lambda_lm = eigs.eigenvalues()(0);
    if (lambda_lm < 0) {
      out.lambda_min = lambda_lm;
      out.vector = eigs.eigenvectors().col(0);
      out.converged = true;
      return out;
    }
  }
  // All eigenvalues of S − λ_lm I are ≤ 0 (up to the estimate's error): its largest-magnitude
  // one is λ_min − λ_lm.
  op.shift = 1.05 * lambda_lm;
  Spectra::SymEigsSolver<CertificateOp> eigs(op, 1, ncv);
  eigs.init();
  eigs.compute(Spectra::SortRule::LargestMagn, 10000, 1e-10);
  out.converged = eigs.info() == Spectra::CompInfo::Successful;
  if (eigs.eigenvalues().size() == 0) {
    throw std::runtime_error("certificateMinimumEigenpair: Lanczos returned no eigenvalue");
  }
  out.lambda_min = eigs.eigenvalues()(0) + op.shift;
  out.vector = eigs.eigenvectors().col(0);
  return out;
}

double certify(const SESyncProblem& problem, const Eigen::MatrixXd& X) {
  return certificateMinimumEigenpair(problem, X).lambda_min;
}

template <class G>
double certify(const PoseGraph<G>& graph, const std::vector<G>& poses) {
  if (static_cast<int>(poses.size()) != graph.numPoses()) {
    throw std::invalid_argument("certify: poses do not match the graph");
  }
  const SESyncProblem problem(graph.numPoses(), G::kDim, sesyncMeasurements(graph));
  return certify(problem, rotationBlocks(poses));
}

template <class G>
RtrSummary solveRtr(const PoseGraph<G>& graph, std::vector<G>* poses, const RtrOptions& options) {
  constexpr int d = G::kDim;
  const auto start = Clock::now();
  const SerialOpenMP serial;
  if (poses == nullptr) throw std::invalid_argument("solveRtr: poses is null");
  requireRelativePoseEdgesOnly(graph);
  if (options.initial_rank < d || options.max_rank < options.initial_rank) {
    throw std::invalid_argument("solveRtr: need d ≤ initial_rank ≤ max_rank (got " +
                                std::to_string(options.initial_rank) + ", " +
                                std::to_string(options.max_rank) + ")");
  }
  if (graph.has_initial_estimate && static_cast<int>(graph.poses.size()) != graph.numPoses()) {
    throw std::invalid_argument("solveRtr: graph.poses does not match graph.ids");
  }
  for (int g : graph.gaugeIndices()) {
    if (g < 0 || g >= graph.numPoses()) {
      throw std::invalid_argument("solveRtr: gauge index out of range: " + std::to_string(g));
    }
  }
  RtrSummary summary;
  const int n = graph.numPoses();
  if (n <= 1) {
    poses->assign(n, graph.has_initial_estimate ? graph.poses.front() : G::Identity());
    summary.certified = summary.relaxation_solved = true;
    summary.rank = d;
    summary.F_rounded = summary.F_final = objective(graph, *poses);
    summary.message = "trivial graph";
    summary.time_s = secondsSince(start);
    return summary;
  }

  // The problem: data matrices and factorisations.
  auto t0 = Clock::now();
  const SESyncProblem problem(n, d, sesyncMeasurements(graph), options.preconditioner,
                              options.preconditioner_max_condition);
  // Chordal initialisation, lifted to rank r₀ by zero columns.
  const std::vector<G> chordal = chordalInitialization(graph);
  summary.time_problem_s = secondsSince(t0);

  Eigen::MatrixXd X0 = Eigen::MatrixXd::Zero(d * n, options.initial_rank);
  X0.leftCols(d) = rotationBlocks(chordal);
  PointData point = evaluate(problem, std::move(X0));
  summary.sesync_objective_initial = point.f;
  int rank = options.initial_rank;
  double radius = 0;  // each level starts with the radius the previous one ended with
  RtrOptions level_options = options;
  bool refined = false;  // this level was resumed with the gradient criteria alone
  for (;;) {
    t0 = Clock::now();
    LevelResult level = riemannianTrustRegion(problem, std::move(point), level_options, radius);
    radius = level.radius;
    summary.time_optimization_s += secondsSince(t0);
    summary.rtr_iterations += level.iterations;
    summary.tcg_iterations += level.tcg_iterations;
    point = std::move(level.point);
    if (level.stop == "cancelled" || options.cancel.cancelled()) {
      summary.cancelled = true;
      summary.message = "cancelled at rank " + std::to_string(rank) + " after " +
                        std::to_string(summary.rtr_iterations) + " RTR iterations";
      break;
    }
    t0 = Clock::now();
    double lambda_min = 0;
    Eigen::VectorXd direction;
    const bool psd = problem.verifyFullCertificate(point.lambda, options.certificate_tolerance,
                                                   &lambda_min, &direction);
    if (options.verbose) {
      std::cerr << "rank " << rank << ": f " << point.f << " after " << level.iterations
                << " RTR iterations (" << level.stop << "), certificate "
                << (psd ? "PSD" : "not PSD") << "\n";
    }
    const bool first_order = level.stop == "gradient" || level.stop == "preconditioned gradient";
    if (!psd && !first_order && !refined) {
      // The level stopped on a small decrease or step before the gradient tolerance: the
      // point is not critical enough for the certificate to mean much. Resume the same level
      // with only the gradient criteria before treating it as a saddle.
      summary.time_certificate_s += secondsSince(t0);
      refined = true;
      level_options.relative_decrease_tolerance = 0;
      level_options.step_tolerance = 0;
      continue;
    }
    refined = false;
    level_options = options;
    if (psd) {
      summary.time_certificate_s += secondsSince(t0);
      summary.lambda_min = lambda_min;
      summary.relaxation_solved = true;
      break;
    }
    // Not PSD: a direction of negative curvature from the full certificate's shift-invert
    // eigenvector (its Rayleigh quotient in Q − Λ), or from Lanczos on Q − Λ itself.
    MinimumEigenpair eig;
    if (direction.size() > 0) {
      eig.vector = direction;
      eig.lambda_min = direction.dot(problem.certificateProduct(point.lambda, direction));
    }
    if (!(eig.lambda_min < -options.certificate_tolerance)) {
      try {
        eig = certificateMinimumEigenpair(problem, point.X);
      } catch (const std::runtime_error& e) {
        summary.time_certificate_s += secondsSince(t0);
        summary.message = std::string("not certified: ") + e.what();
        break;
      }
    }
    summary.time_certificate_s += secondsSince(t0);
    summary.lambda_min = eig.lambda_min;
    if (options.verbose) {
      std::cerr << "  lambda_min(S full) " << lambda_min << ", curvature " << eig.lambda_min
                << "\n";
    }
    if (eig.lambda_min >= -options.certificate_tolerance) {
      summary.message = "certificate inconclusive: S + ηI not PD but Lanczos λ_min " +
                        std::to_string(eig.lambda_min);
      break;
    }
    if (rank >= options.max_rank) {
      summary.message = "not certified: reached max_rank " + std::to_string(rank);
      break;
    }
    if (options.cancel.cancelled()) {
      summary.cancelled = true;
      summary.message = "cancelled at rank " + std::to_string(rank) + " before the saddle escape";
      break;
    }
    t0 = Clock::now();
    PointData lifted;
    const bool escaped = escapeSaddle(problem, point, eig.vector, options, &lifted);
    summary.time_optimization_s += secondsSince(t0);
    if (!escaped) {
      summary.message =
          "not certified: could not escape the saddle at rank " + std::to_string(rank);
      break;
    }
    point = std::move(lifted);
    ++rank;
    const double gnorm = std::sqrt(inner(point.grad, point.grad));
    if (gnorm <= options.gradient_tolerance) {
      // A weak saddle: make the next level go below the gradient it starts with.
      level_options.gradient_tolerance = 0.1 * gnorm;
      level_options.preconditioned_gradient_tolerance =
          std::min(options.preconditioned_gradient_tolerance, 0.1 * gnorm);
    }
  }
  summary.rank = rank;
  summary.sesync_objective = point.f;

  // Rounding and translation recovery.
  t0 = Clock::now();
  const Eigen::MatrixXd R = roundToRotations(point.X, d);
  const Eigen::MatrixXd T = problem.recoverTranslations(R);
  summary.suboptimality_bound = problem.objective(R) - point.f;
  if (summary.relaxation_solved) {
    summary.certified =
        summary.suboptimality_bound <= options.relative_gap_tolerance * std::abs(point.f);
    summary.message = "relaxation solved at rank " + std::to_string(rank) +
                      (summary.certified ? ", exact: certified global optimum"
                                         : ", not exact: suboptimality bound " +
                                               std::to_string(summary.suboptimality_bound));
  }
  std::vector<G> estimate(n);
  G* tag = nullptr;
  for (int i = 0; i < n; ++i) {
    const Eigen::Matrix<double, d, d> Ri = R.middleRows(d * i, d).transpose();
    const Eigen::Matrix<double, d, 1> ti = T.row(i).transpose();
    estimate[i] = makePose(Ri, ti, tag);
  }
  // Gauge: the first gauge pose at its file value (or the identity).
  const std::vector<int> gauge = graph.gaugeIndices();
  const int a = gauge.front();
  const G target = graph.has_initial_estimate ? graph.poses[a] : G::Identity();
  const G align = target.compose(estimate[a].inverse());
  for (auto& x : estimate) x = align.compose(x);
  if (graph.has_initial_estimate) {
    for (int g : gauge) estimate[g] = graph.poses[g];
  }
  summary.F_rounded = objective(graph, estimate);
  summary.time_rounding_s = secondsSince(t0);

  summary.F_final = summary.F_rounded;
  if (options.polish) {
    t0 = Clock::now();
    BatchOptions polish_options = options.polish_options;
    polish_options.cancel = options.cancel;
    const BatchSummary polish = solveBatch(graph, &estimate, polish_options);
    if (options.verbose) {
      std::cerr << "polish: " << polish.iterations << " iterations, F " << polish.F_initial
                << " -> " << polish.F_final << " (" << toString(polish.termination) << ")\n";
    }
    summary.time_polish_s = secondsSince(t0);
    summary.F_final = objective(graph, estimate);
    if (polish.termination == Termination::kDiverged) {
      summary.message += "; polish diverged: " + polish.message;
    } else if (polish.termination == Termination::kCancelled) {
      summary.cancelled = true;
      summary.message += "; polish cancelled";
    }
  }
  *poses = std::move(estimate);
  summary.time_s = secondsSince(start);
  return summary;
}

template RtrSummary solveRtr(const PoseGraph<SE2>&, std::vector<SE2>*, const RtrOptions&);
template RtrSummary solveRtr(const PoseGraph<SE3>&, std::vector<SE3>*, const RtrOptions&);
template double certify(const PoseGraph<SE2>&, const std::vector<SE2>&);
template double certify(const PoseGraph<SE3>&, const std::vector<SE3>&);

}  // namespace arbor
