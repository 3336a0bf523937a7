// The smoother's side of asynchronous relinearisation (RelinearizationMode::kAsync;
// docs/design.md, "Asynchronous relinearisation"): at most one relinearisation job
// (async_relinearization.h) and at most one catch-up in flight, what changed since the job's
// snapshot, when each is due to be swapped in, and the buffers kept between jobs. A catch-up is
// a copy of the smoother's state (`State`) that folds what arrived since the snapshot into the
// job's tree on a background thread (background_job.h); relinearization_swap.h builds the bases
// the smoother swaps in.
//
// Invariants: at most one of the job and the catch-up is pending; `since` is empty while
// neither is (the smoother records into it only while pending()); the catch-up's bookkeeping
// (poses, factors, theta_at_catch_up) describes the smoother as it was when the pending
// catch-up started.
#pragma once

#include <algorithm>
#include <functional>
#include <memory>
#include <utility>
#include <vector>

#include "arbor_slam/bayestree/async_relinearization.h"
#include "arbor_slam/bayestree/background_job.h"
#include "arbor_slam/bayestree/incremental_smoother.h"
#include "arbor_slam/bayestree/relinearization_swap.h"

namespace arbor::bayestree {

template <class G, class State>
class RelinearizationJobs {
 public:
  /// A job or a catch-up in flight (no relinearisation check runs meanwhile).
  bool pending() const { return job_.pending() || catch_up_.pending(); }
  /// What changed since the snapshot (recorded by the smoother while pending()).
  SinceSnapshot since;
  /// setSecondCoreBusy: no new job or catch-up starts while set.
  bool second_core_busy = false;

  /// Starts a job on `s` (its scalars set; theta, fixed, relinearized as the smoother's at the
  /// check, with Θ_M := Θ_M ⊕ Δ_M applied here) with the first `num_factors` of `factors`,
  /// copied into the last snapshot's buffer: its pages are in memory already, where a fresh
  /// copy faults every page in on the update path (up to 117 ms at 200,000 poses, measured).
  void startJob(RelinearizationSnapshot<G> s, const std::vector<Factor<G>>& factors,
                int num_factors, const std::vector<typename G::Tangent>& delta, bool synchronous) {
    s.factors = std::move(snapshot_factors_);
    s.factors.clear();
    const auto wanted = static_cast<size_t>(num_factors);
    if (s.factors.capacity() < wanted) s.factors.reserve(wanted + wanted / 4);
    s.factors.insert(s.factors.end(), factors.begin(), factors.begin() + num_factors);
    std::sort(s.relinearized.begin(), s.relinearized.end());
    for (int v : s.relinearized) {
      s.theta_before.push_back(s.theta[v]);
      s.theta[v] = s.theta[v].retract(delta[v]);
      s.theta[v].normalize();
    }
    since.clear();
    job_.start(std::move(s), synchronous, std::exchange(replaced, {}));
  }
  /// The job's swap is due: it is done (or, with swap_after_updates, this is its update: the
  /// swap waits for it).
  bool jobSwapDue(int update, const AsyncRelinearizationOptions& o) const {
    if (!job_.pending()) return false;
    if (o.swap_after_updates > 0) return update >= job_.snapshot().update + o.swap_after_updates;
    return job_.done();
  }
  /// Takes the finished job as a base; *relinearized: |M| of its snapshot.
  SwapBase<G> takeJob(int* relinearized) {
    RelinearizationSnapshot<G> snap;
    RelinearizedTree<G> job;
    job_.take(&snap, &job);
    *relinearized = static_cast<int>(snap.relinearized.size());
    SwapBase<G> base = baseOfJob(std::move(snap), std::move(job));
    snapshot_factors_ = std::move(snap.factors);  // baseOfJob reads its size only
    return base;
  }

  /// Starts a catch-up: `shadow` runs `work` (in the background unless `synchronous`); the
  /// smoother has `poses` poses and `factors` factors at Θ = `theta` now, and records what
  /// changes from here on as since the snapshot.
  void startCatchUp(std::unique_ptr<State> shadow, std::function<void(State&)> work,
                    const std::vector<G>& theta, int factors, int relinearized, bool first_round,
                    bool synchronous, int update) {
    if (first_round) {
      catch_up_relinearized_ = relinearized;
      catch_up_rounds_ = 0;
    }
    ++catch_up_rounds_;
    since.clear();
    theta_at_catch_up_ = theta;
    catch_up_poses_ = static_cast<int>(theta.size());
    catch_up_factors_ = factors;
    catch_up_.start(std::move(shadow), std::move(work), synchronous, update);
  }
  /// The catch-up's swap is due: it is done (or, with swap_after_updates, this is the update
  /// after its start: the swap waits for it).
  bool catchUpSwapDue(int update, const AsyncRelinearizationOptions& o) const {
    if (!catch_up_.pending()) return false;
    if (o.swap_after_updates > 0) return update >= catch_up_.startedAt() + 1;
    return catch_up_.done();
  }
  /// catch_up_max_factors: a finished catch-up whose swap would fold in more than that many
  /// factors (of `factors_now`, queued included) hands its tree to another catch-up instead,
  /// at most catch_up_max_rounds a job.
  bool catchUpAgain(int factors_now, const AsyncRelinearizationOptions& o, bool allowed) const {
    const int arrived = factors_now - catch_up_factors_;
    return o.catch_up_max_factors > 0 && arrived > o.catch_up_max_factors &&
           catch_up_rounds_ < o.catch_up_max_rounds && allowed;
  }
  /// Takes the finished catch-up's state; `base` gets what its tree was built from (the first
  /// n poses and f factors; Θ before: the smoother's when it started, every pose). The caller
  /// moves the state's tree, linearisations, solve, Δ and Θ into `base`.
  std::unique_ptr<State> takeCatchUp(SwapBase<G>* base) {
    std::unique_ptr<State> shadow = catch_up_.take();
    base->n = catch_up_poses_;
    base->f = catch_up_factors_;
    base->all_relinearized = true;
    base->theta_before = std::move(theta_at_catch_up_);
    theta_at_catch_up_.clear();
    return shadow;
  }
  /// |M| of the snapshot of the job the catch-up continues.
  int catchUpRelinearized() const { return catch_up_relinearized_; }

  /// Waits for whatever is in flight and drops it (relinearizeAll: every variable is
  /// relinearised anyway).
  void abandon() {
    job_.abandon();
    catch_up_.abandon();
    theta_at_catch_up_.clear();
    since.clear();
  }
  /// Frees the buffers kept for the next job (relinearizeAll re-eliminates everything).
  void dropBuffers() {
    replaced = RelinearizedTree<G>();
    std::vector<Factor<G>>().swap(snapshot_factors_);
  }

  /// What the last swap replaced (its tree, linearisations, solve and Δ), freed by the next
  /// job's thread before its work (AsyncRelinearization::start).
  RelinearizedTree<G> replaced;

 private:
  AsyncRelinearization<G> job_;
  BackgroundJob<State> catch_up_;
  int catch_up_poses_ = 0, catch_up_factors_ = 0, catch_up_relinearized_ = 0;
  int catch_up_rounds_ = 0;
  std::vector<G> theta_at_catch_up_;
  std::vector<Factor<G>> snapshot_factors_;  // the last snapshot's array, for the next copy
};

}  // namespace arbor::bayestree
