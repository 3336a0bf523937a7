#include "arbor_slam/bayestree/async_relinearization.h"

#include <ctime>
#include <utility>

#include "arbor_slam/bayestree/top_elimination.h"
#include "arbor_slam/bayestree/update_threads.h"
#include "arbor_slam/core/thread_priority.h"

namespace arbor::bayestree {
namespace {

double threadCpuSeconds() {
  timespec t{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &t);
  return static_cast<double>(t.tv_sec) + 1e-9 * static_cast<double>(t.tv_nsec);
}

// One elimination of the whole graph of `s` at Θ = theta (s.theta's place in the listing).
template <class G>
RelinearizedTree<G> eliminateAt(const RelinearizationSnapshot<G>& s, const std::vector<G>& theta) {
  RelinearizedTree<G> out;
  const int n = static_cast<int>(theta.size());
  UpdateThreads threads(1);
  out.tree.cached_factors = s.cached_factors;
  for (int v = 0; v < n; ++v) {
    out.tree.addVariable();
    out.factors.addVariable();
    out.solve.addVariable();
    threads.addVariable();
  }
  out.delta.assign(static_cast<size_t>(n), typename G::Tangent(G::Tangent::Zero()));
  // Factors at weight 0 are added but stay out of the structure (LinearizedFactors::attached).
  std::vector<int> all_factors;
  for (const auto& e : s.factors) {
    const int f = out.factors.add(e);
    if (out.factors.attached[f]) all_factors.push_back(f);
  }
  std::vector<int> variables;
  for (int v = 0; v < n; ++v)
    if (!s.fixed[v]) variables.push_back(v);
  // Alg. 4 with J = every variable (relinearizeAll's pass): Alg. 4 step 2 linearises every
  // factor at Θ, steps 4–5 order the whole graph afresh (unconstrained) and eliminate it; no
  // orphans. Then Alg. 7 over every clique.
  const std::vector<int> no_orphans;
  const typename TopElimination<G>::Input in{variables,
                                             no_orphans,
                                             nullptr,
                                             all_factors,
                                             theta,
                                             s.fixed,
                                             s.nested_dissection_min,
                                             s.nested_dissection_try_flops};
  TopElimination<G> elimination;
  const auto eliminated = elimination.run(in, &out.tree, &out.factors, &threads);
  out.cliques = eliminated.cliques;
  out.indeterminate = eliminated.indeterminate;
  out.tree.releaseFreeStorage();
  out.solve.run(&out.tree, /*full=*/true, 0.0, /*budget=*/0.0, &out.delta, &threads);
  return out;
}

// F = Σ w eᵀΩe of the snapshot's factors at `theta`.
template <class G>
double weightedObjective(const RelinearizationSnapshot<G>& s, const std::vector<G>& theta) {
  double f = 0;
  for (const auto& e : s.factors) f += e.inlierWeight() * e.cost(theta);
  return f;
}

}  // namespace

template <class G>
RelinearizedTree<G> relinearizeSnapshot(const RelinearizationSnapshot<G>& s) {
  const double cpu0 = threadCpuSeconds();
  RelinearizedTree<G> out = eliminateAt(s, s.theta);
  if (s.iterations > 1) {
    // Gauss–Newton on the snapshot (relinearizeAll's iteration, on the copy): step, and
    // re-eliminate at the new Θ while F falls by more than the tolerance.
    std::vector<G> theta = s.theta, next;
    double F = weightedObjective(s, theta);
    for (int it = 1; it < s.iterations; ++it) {
      double scale = 1.0, F_next = F;
      bool lower = false;
      for (int halving = 0; halving <= 5 && !lower; ++halving, scale *= 0.5) {
        next = theta;
        for (size_t v = 0; v < next.size(); ++v) {
          if (s.fixed[v]) continue;
          next[v] = theta[v].retract(scale * out.delta[v]);
          next[v].normalize();
        }
        F_next = weightedObjective(s, next);
        lower = F_next < F;
      }
      if (!lower) break;  // no step lowers F: the tree at Θ stays
      const bool settled = F - F_next <= s.relative_tolerance * F;
      theta.swap(next);
      F = F_next;
      out = RelinearizedTree<G>();  // one tree at a time
      out = eliminateAt(s, theta);
      out.iterations = it + 1;
      out.theta = theta;
      if (settled) break;
    }
  }
  out.cpu_seconds = threadCpuSeconds() - cpu0;
  return out;
}

template <class G>
void AsyncRelinearization<G>::Job::run() {
  try {
    free_first = RelinearizedTree<G>();
    result = relinearizeSnapshot(snapshot);
  } catch (...) {
    error = std::current_exception();
  }
  done.store(true);
}

template <class G>
AsyncRelinearization<G>::~AsyncRelinearization() {
  join();
}

template <class G>
AsyncRelinearization<G>::AsyncRelinearization(const AsyncRelinearization& other) {
  if (!other.job_) return;
  other.join();
  job_ = std::make_unique<Job>();
  job_->snapshot = other.job_->snapshot;
  job_->result = other.job_->result;
  job_->error = other.job_->error;
  job_->done.store(true);
}

template <class G>
AsyncRelinearization<G>& AsyncRelinearization<G>::operator=(const AsyncRelinearization& other) {
  if (this != &other) {
    AsyncRelinearization copy(other);
    *this = std::move(copy);
  }
  return *this;
}

template <class G>
AsyncRelinearization<G>& AsyncRelinearization<G>::operator=(AsyncRelinearization&& other) noexcept {
  if (this != &other) {
    join();
    job_ = std::move(other.job_);
  }
  return *this;
}

template <class G>
void AsyncRelinearization<G>::join() const {
  if (job_ && job_->thread.joinable()) job_->thread.join();
}

template <class G>
void AsyncRelinearization<G>::start(RelinearizationSnapshot<G> snapshot, bool synchronous,
                                    RelinearizedTree<G> free_first) {
  join();
  job_ = std::make_unique<Job>();
  job_->snapshot = std::move(snapshot);
  job_->free_first = std::move(free_first);
  Job* job = job_.get();
  if (synchronous) {
    job->run();
    return;
  }
  job->thread = std::thread([job] {
    lowerThisThreadsPriority();  // the update path comes first
    job->run();
  });
}

template <class G>
void AsyncRelinearization<G>::take(RelinearizationSnapshot<G>* snapshot,
                                   RelinearizedTree<G>* result) {
  join();
  std::unique_ptr<Job> job = std::move(job_);
  if (job->error) std::rethrow_exception(job->error);
  *snapshot = std::move(job->snapshot);
  *result = std::move(job->result);
}

template <class G>
void AsyncRelinearization<G>::abandon() {
  join();
  job_.reset();
}

template struct RelinearizedTree<SE2>;
template struct RelinearizedTree<SE3>;
template RelinearizedTree<SE2> relinearizeSnapshot(const RelinearizationSnapshot<SE2>&);
template RelinearizedTree<SE3> relinearizeSnapshot(const RelinearizationSnapshot<SE3>&);
template class AsyncRelinearization<SE2>;
template class AsyncRelinearization<SE3>;

}  // namespace arbor::bayestree
