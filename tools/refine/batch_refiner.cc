#include "arbor_slam/tools/refine/batch_refiner.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <exception>
#include <stdexcept>
#include <thread>

#include "arbor_slam/core/elapsed.h"
#include "arbor_slam/core/serial_openmp.h"
#include "arbor_slam/core/thread_priority.h"

namespace arbor::refine {

namespace {

void requireRefining(BatchSolver solver) {
  if (!info(solver).refines) {
    throw std::invalid_argument("batch refinement runs " + batchSolverNames(true, " or ") +
                                ", not " + toString(solver));
  }
}

template <class G>
double rotationAngle(const G& a, const G& b) {
  const Eigen::Matrix<double, G::kDim, G::kDim> r = a.rotation().transpose() * b.rotation();
  const double c = std::clamp((r.trace() - (G::kDim - 2)) / 2.0, -1.0, 1.0);
  return std::acos(c);  // SO(2): tr = 2cosθ; SO(3): tr = 1 + 2cosθ
}

}  // namespace

Verdict pickWinner(double F_incremental, double F_lm, double F_rtr) {
  // Keep-best: the lowest F; a batch estimate must beat the incremental one by > 1e-9 relative
  // (rebuilding for nothing costs an update's worth of latency); between LM and RTR the lower.
  struct Candidate {
    const char* name;
    double F;
  };
  const Candidate candidates[] = {{"incremental", F_incremental}, {"lm", F_lm}, {"rtr", F_rtr}};
  const Candidate* best = &candidates[0];
  for (const Candidate& c : candidates) {
    if (&c == &candidates[0] || !std::isfinite(c.F)) continue;
    const bool beats_incremental = c.F < F_incremental - 1e-9 * std::abs(F_incremental);
    if (beats_incremental && (best == &candidates[0] || c.F <= best->F)) best = &c;
  }
  double runner_up = std::numeric_limits<double>::infinity();
  for (const Candidate& c : candidates) {
    if (&c != best && std::isfinite(c.F)) runner_up = std::min(runner_up, c.F);
  }
  Verdict v;
  v.winner = best->name;
  v.margin = std::isfinite(runner_up) ? std::abs(runner_up - best->F) : 0.0;
  v.margin_relative = v.margin / std::max(std::abs(best->F), 1e-300);
  return v;
}

template <class G>
BatchOutcome<G> solveSnapshot(BatchSolver solver, const PoseGraph<G>& snapshot,
                              const CancellationToken& cancel) {
  requireRefining(solver);
  BatchSolveSettings settings;
  settings.cancel = cancel;
  BatchOutcome<G> out;
  BatchRun& run = out.run;
  const std::vector<G>& incremental = snapshot.poses;
  run.poses = snapshot.numPoses();
  run.edges = snapshot.numEdges();
  run.F_incremental = objective(snapshot, incremental);

  // Plain LM from the incremental estimate: the batch itself for lm, the keep-best rival of RTR.
  auto t0 = std::chrono::steady_clock::now();
  std::vector<G> lm = incremental;
  const BatchSolve lm_solve =
      runBatchSolver(BatchSolver::kLevenbergMarquardt, snapshot, &lm, settings);
  run.cancelled = lm_solve.cancelled;
  run.lm_time_s = secondsSince(t0);
  run.F_lm = objective(snapshot, lm);

  struct Candidate {
    const char* name;
    double F;
    const std::vector<G>* poses;
  };
  std::vector<Candidate> candidates{{"incremental", run.F_incremental, &incremental},
                                    {"lm", run.F_lm, &lm}};
  std::vector<G> rtr;
  if (solver == BatchSolver::kRtr && !run.cancelled) {
    t0 = std::chrono::steady_clock::now();
    const BatchSolve s = runBatchSolver(BatchSolver::kRtr, snapshot, &rtr, settings);
    run.cancelled = s.cancelled;
    run.rtr_time_s = secondsSince(t0);
    run.F_rtr = objective(snapshot, rtr);
    run.rank = s.rtr->rank;
    run.lambda_min = s.rtr->lambda_min;
    run.certified = s.rtr->certified;
    run.iterations = s.iterations;
    candidates.push_back({"rtr", run.F_rtr, &rtr});
    out.batch = rtr;
  } else {
    run.iterations = lm_solve.iterations;
    out.batch = lm;
  }
  run.time_s = run.lm_time_s + run.rtr_time_s;
  run.F_batch = objective(snapshot, out.batch);
  run.relative_gap = (run.F_incremental - run.F_batch) / std::max(run.F_batch, 1e-300);

  const Verdict verdict = pickWinner(run.F_incremental, run.F_lm, run.F_rtr);
  run.winner = verdict.winner;
  run.margin = verdict.margin;
  run.margin_relative = verdict.margin_relative;
  for (const Candidate& c : candidates) {
    if (verdict.winner == c.name && c.poses != &incremental && !run.cancelled) out.best = *c.poses;
  }
  out.incremental = incremental;

  const G inc0 = incremental[0].inverse(), bat0 = out.batch[0].inverse();
  for (size_t k = 0; k < incremental.size(); ++k) {
    const G a = inc0.compose(incremental[k]), b = bat0.compose(out.batch[k]);
    run.max_translation_diff =
        std::max(run.max_translation_diff, (a.translation() - b.translation()).norm());
    run.max_rotation_diff = std::max(run.max_rotation_diff, rotationAngle(a, b));
  }
  return out;
}

template <class G>
GncOptions gncOptionsOf(const OnlineGnc<G>& online, std::vector<KernelKind> kernels) {
  GncOptions gnc;
  gnc.kernel = online.options().kernel;
  gnc.threshold = online.threshold();
  gnc.kernels = std::move(kernels);
  return gnc;
}

template <class G>
OnlineClassification robustStartOf(const OnlineSmoother<G>& smoother, std::vector<char> held_out) {
  const OnlineGnc<G>* online = smoother.gnc();
  if (online == nullptr)
    throw std::invalid_argument("robustStartOf: the smoother has no robust smoothing");
  if (!smoother.finalized()) return {};
  OnlineClassification c =
      onlineBounds(online->threshold(), online->thresholdAtEnd(), robust_constants::kRecheckMargin);
  c.held_out = std::move(held_out);
  return c;
}

template <class G>
double robustCost(const PoseGraph<G>& graph, const std::vector<G>& poses,
                  const std::vector<char>& judged, const GncOptions& gnc) {
  // Σρ = F − Σ_judged (s − ρ(s)), F = Σ eᵀΩe over every edge and prior.
  const double c2 = gnc.threshold;
  double cost = objective(graph, poses);
  for (size_t e = 0; e < graph.edges.size(); ++e) {
    if (!judged[e]) continue;
    const KernelKind kernel =
        e < gnc.kernels.size() && gnc.kernels[e] != KernelKind::kNone ? gnc.kernels[e] : gnc.kernel;
    const auto& edge = graph.edges[e];
    const double s = edge.cost(poses[edge.i], poses[edge.j]);
    const double rho = kernel == KernelKind::kTruncatedLeastSquares
                           ? std::min(s, c2)
                           : RobustKernel{kernel, c2, 1.0}.rho(s);
    cost -= s - rho;
  }
  return cost;
}

template <class G>
BatchOutcome<G> solveRobustSnapshot(BatchSolver solver, const PoseGraph<G>& snapshot,
                                    const std::vector<char>& judged, GncOptions gnc,
                                    const OnlineClassification& online) {
  requireRefining(solver);
  if (judged.size() != snapshot.edges.size())
    throw std::invalid_argument("solveRobustSnapshot: " + std::to_string(judged.size()) +
                                " marks for " + std::to_string(snapshot.edges.size()) + " edges");
  BatchOutcome<G> out;
  BatchRun& run = out.run;
  run.robust = true;
  const std::vector<G>& incremental = snapshot.poses;
  run.poses = snapshot.numPoses();
  run.edges = snapshot.numEdges();
  for (char j : judged) run.judged += j;
  auto rho = [&](const std::vector<G>& x) { return robustCost(snapshot, x, judged, gnc); };
  run.F_incremental = rho(incremental);

  // GNC from the incremental estimate and the online classification, trusting what the online
  // GNC trusts.
  GncOptions options = gnc;
  options.trust_odometry = false;
  options.trusted.assign(judged.size(), 0);
  for (size_t e = 0; e < judged.size(); ++e) options.trusted[e] = judged[e] ? 0 : 1;
  auto t0 = std::chrono::steady_clock::now();
  std::vector<G> estimate = incremental;
  const GncFromOnline from = solveGncFromOnline(snapshot, options, online, &estimate);
  const GncResult& result = from.gnc;
  run.threshold = result.threshold;
  run.cancelled = result.cancelled;
  run.lm_time_s = secondsSince(t0);
  run.F_lm = rho(estimate);
  run.iterations = result.iterations;
  run.rejected = result.rejected;
  out.batch = estimate;

  // rtr: the staircase on GNC's inlier set, certifying that inlier problem.
  std::vector<G> certified;
  if (solver == BatchSolver::kRtr && !run.cancelled) {
    t0 = std::chrono::steady_clock::now();
    certified = estimate;
    try {
      GncResult classified = result;
      RtrOptions rtr;
      rtr.cancel = gnc.cancel;
      const CertifiedInliers c = certifyInliers(snapshot, &classified, &certified, rtr,
                                                /*max_passes=*/5, online.c2_take_back);
      run.cancelled = c.rtr.cancelled;
      run.F_rtr = rho(certified);
      run.rank = c.rtr.rank;
      run.lambda_min = c.rtr.lambda_min;
      run.certified = c.rtr.certified;
      run.rejected = classified.rejected;
      out.batch = certified;
    } catch (const std::exception& e) {
      run.rtr_skipped = e.what();
      certified.clear();
    }
    run.rtr_time_s = secondsSince(t0);
  }
  run.time_s = run.lm_time_s + run.rtr_time_s;
  run.F_batch = rho(out.batch);
  run.relative_gap = (run.F_incremental - run.F_batch) / std::max(run.F_batch, 1e-300);

  const Verdict verdict = pickWinner(run.F_incremental, run.F_lm, run.F_rtr);
  run.winner = verdict.winner == "lm" ? "gnc" : verdict.winner;
  run.margin = verdict.margin;
  run.margin_relative = verdict.margin_relative;
  if (verdict.winner == "lm" && !run.cancelled) out.best = estimate;
  if (verdict.winner == "rtr" && !run.cancelled) out.best = certified;
  out.incremental = incremental;
  const G inc0 = incremental[0].inverse(), bat0 = out.batch[0].inverse();
  for (size_t k = 0; k < incremental.size(); ++k) {
    const G a = inc0.compose(incremental[k]), b = bat0.compose(out.batch[k]);
    run.max_translation_diff =
        std::max(run.max_translation_diff, (a.translation() - b.translation()).norm());
    run.max_rotation_diff = std::max(run.max_rotation_diff, rotationAngle(a, b));
  }
  return out;
}

template <class G>
std::vector<G> seedValues(const OnlineSmoother<G>& smoother, const BatchOutcome<G>& outcome) {
  const size_t n = outcome.best.size();
  if (n != outcome.incremental.size() || n > static_cast<size_t>(smoother.stats().poses)) {
    throw std::invalid_argument("seedValues: " + std::to_string(n) +
                                " batch poses do not fit the snapshot or the smoother");
  }
  const std::vector<G> current = smoother.smoother().estimate();
  std::vector<G> seed(n);
  for (size_t k = 0; k < n; ++k) {  // the batch's correction, applied on the left
    seed[k] = outcome.best[k].compose(outcome.incremental[k].inverse()).compose(current[k]);
  }
  return seed;
}

template <class G>
struct BatchRefiner<G>::Flight {
  PoseGraph<G> snapshot;
  OnlineSmoother<G>* busy = nullptr;  ///< told its second core is free again by collect
  std::vector<char> judged;           ///< robust: per snapshot edge, weighted by GNC
  std::optional<GncOptions> gnc;      ///< robust: the smoother's kernel and c²
  OnlineClassification online;        ///< robust: what the smoother rejects, and its bounds
  std::int64_t update = 0;
  int updates_during = 0;
  BatchOutcome<G> outcome;
  std::exception_ptr error;
  std::atomic<bool> done{false};
  std::thread thread;

  void solve(BatchSolver solver, const CancellationToken& cancel) {
    try {
      if (gnc) {
        GncOptions options = *gnc;
        options.cancel = cancel;  // GNC hands it to its solves; the staircase gets it too
        outcome = solveRobustSnapshot(solver, snapshot, judged, options, online);
      } else {
        outcome = solveSnapshot(solver, snapshot, cancel);
      }
    } catch (...) {
      error = std::current_exception();
    }
    done.store(true);
  }
  ~Flight() {
    if (thread.joinable()) thread.join();
  }
};

template <class G>
BatchRefiner<G>::BatchRefiner(RefinerOptions options) : options_(options) {
  requireRefining(options_.solver);
  if (options_.every < 0) {
    throw std::invalid_argument("--batch-every must be >= 0, not " +
                                std::to_string(options_.every));
  }
}

template <class G>
BatchRefiner<G>::~BatchRefiner() = default;

template <class G>
bool BatchRefiner<G>::due(std::int64_t updates) const {
  return options_.every > 0 && updates > 0 && updates % options_.every == 0;
}

template <class G>
bool BatchRefiner<G>::inFlight() const {
  return flight_ != nullptr;
}

template <class G>
bool BatchRefiner<G>::running() const {
  return flight_ && !flight_->done.load();
}

template <class G>
bool BatchRefiner<G>::start(OnlineSmoother<G>& smoother, std::int64_t update) {
  if (flight_ || smoother.smoother().relinearizationPending()) {
    ++skipped_;
    return false;
  }
  SnapshotJudgement judgement;
  PoseGraph<G> snapshot = smoother.snapshot(&judgement);
  if (snapshot.numPoses() < 2 || snapshot.numEdges() == 0) return false;
  flight_ = std::make_unique<Flight>();
  flight_->snapshot = std::move(snapshot);
  if (const OnlineGnc<G>* online = smoother.gnc()) {  // robust: GNC as the online one judges
    flight_->gnc = gncOptionsOf(*online, std::move(judgement.kernels));
    flight_->online = robustStartOf(smoother, std::move(judgement.held_out));
    flight_->judged = std::move(judgement.judged);
  }
  flight_->update = update;
  flight_->busy = &smoother;
  if (!options_.synchronous) smoother.setSecondCoreBusy(true);
  Flight* f = flight_.get();
  const BatchSolver solver = options_.solver;
  const CancellationToken cancel = options_.cancel;
  if (options_.synchronous) {
    f->solve(solver, cancel);
  } else {
    f->thread = std::thread([f, solver, cancel] {
      // The smoother's latency comes first: this thread runs at a lower priority and never fans
      // out into OpenMP threads (Eigen, CHOLMOD).
      lowerThisThreadsPriority();
      const SerialOpenMP serial;
      f->solve(solver, cancel);
    });
  }
  return true;
}

template <class G>
void BatchRefiner<G>::noteUpdate() {
  if (running()) ++flight_->updates_during;
}

template <class G>
std::optional<BatchOutcome<G>> BatchRefiner<G>::collect(bool wait) {
  if (!flight_ || (!wait && !flight_->done.load())) return std::nullopt;
  if (flight_->thread.joinable()) flight_->thread.join();
  std::unique_ptr<Flight> f = std::move(flight_);
  f->busy->setSecondCoreBusy(false);
  if (f->error) std::rethrow_exception(f->error);
  BatchOutcome<G> out = std::move(f->outcome);
  out.run.update = f->update;
  out.run.updates_during = f->updates_during;
  ++completed_;
  return out;
}

template <class G>
bool BatchRefiner<G>::reseed(OnlineSmoother<G>& smoother, BatchOutcome<G>* outcome,
                             std::int64_t update) {
  if (!options_.reseed || outcome->best.empty()) return false;
  BatchRun& run = outcome->run;
  const ReseedResult r = smoother.reseed(seedValues(smoother, *outcome), /*only_if_lower=*/true);
  run.reseeded = r.applied;
  run.reseed_rejected = !r.applied;
  run.reseed_s = r.stats.time_s;
  run.reseed_update = update;
  run.F_before_reseed = r.F_before;
  run.F_after_reseed = r.F_rebuilt;
  reseed_s_ += run.reseed_s;
  if (r.applied) ++reseeds_;
  return r.applied;
}

template <class G>
std::vector<BatchRun> BatchRefiner<G>::afterUpdate(OnlineSmoother<G>& smoother,
                                                   std::int64_t updates) {
  std::vector<BatchRun> runs;
  noteUpdate();
  if (auto done = collect(false)) {
    reseed(smoother, &*done, updates);
    runs.push_back(done->run);
  }
  if (due(updates) && start(smoother, updates) && options_.synchronous) {
    auto done = collect(true);
    reseed(smoother, &*done, updates);
    runs.push_back(done->run);
  }
  return runs;
}

template std::vector<SE2> seedValues(const OnlineSmoother<SE2>&, const BatchOutcome<SE2>&);
template std::vector<SE3> seedValues(const OnlineSmoother<SE3>&, const BatchOutcome<SE3>&);
template BatchOutcome<SE2> solveSnapshot(BatchSolver, const PoseGraph<SE2>&,
                                         const CancellationToken&);
template BatchOutcome<SE2> solveRobustSnapshot(BatchSolver, const PoseGraph<SE2>&,
                                               const std::vector<char>&, GncOptions,
                                               const OnlineClassification&);
template BatchOutcome<SE3> solveRobustSnapshot(BatchSolver, const PoseGraph<SE3>&,
                                               const std::vector<char>&, GncOptions,
                                               const OnlineClassification&);
template GncOptions gncOptionsOf(const OnlineGnc<SE2>&, std::vector<KernelKind>);
template GncOptions gncOptionsOf(const OnlineGnc<SE3>&, std::vector<KernelKind>);
template OnlineClassification robustStartOf(const OnlineSmoother<SE2>&, std::vector<char>);
template OnlineClassification robustStartOf(const OnlineSmoother<SE3>&, std::vector<char>);
template double robustCost(const PoseGraph<SE2>&, const std::vector<SE2>&, const std::vector<char>&,
                           const GncOptions&);
template double robustCost(const PoseGraph<SE3>&, const std::vector<SE3>&, const std::vector<char>&,
                           const GncOptions&);
template BatchOutcome<SE3> solveSnapshot(BatchSolver, const PoseGraph<SE3>&,
                                         const CancellationToken&);
template class BatchRefiner<SE2>;
template class BatchRefiner<SE3>;

}  // namespace arbor::refine
