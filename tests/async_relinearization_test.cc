// Tests of asynchronous relinearisation (SmootherOptions::relinearize = kAsync,
// bayestree/async_relinearization.h): after the swap, the estimate is the one relinearising at
// the snapshot and applying the later updates inline gives. Deterministic: the job runs on the
// calling thread, or the swap update waits for the background thread (swap_after_updates); no
// timing.

#include <cstdlib>
#include <random>
#include <vector>

#include "arbor_slam/bayestree/async_relinearization.h"
#include "arbor_slam/bayestree/incremental_smoother.h"
#include "arbor_slam/tests/random_walks.h"

#include <gtest/gtest.h>

namespace arbor {
namespace {

using testing::randomWalk;

SmootherOptions inlineOptions() {
  SmootherOptions o;
  o.threads = 1;
  o.wildfire_threshold = 0;  // every clique below a change is solved: exact comparisons
  o.batch.top_share = 1;     // the ordering differs anyway: keep the inline path plain
  o.batch.reorder_decay = 0;
  return o;
}

SmootherOptions asyncOptions(bool synchronous, int swap_after) {
  SmootherOptions o = inlineOptions();
  o.relinearize = RelinearizationMode::kAsync;
  o.async.min_variables = 1;
  o.async.synchronous = synchronous;
  o.async.swap_after_updates = swap_after;
  return o;
}

template <class G>
double tangentDistance(const std::vector<G>& a, const std::vector<G>& b, int* worst) {
  double d = 0;
  for (size_t v = 0; v < a.size(); ++v) {
    const double e = a[v].between(b[v]).Log().norm();
    if (e > d) {
      d = e;
      *worst = static_cast<int>(v);
    }
  }
  return d;
}

/// What happens to both smoothers during a job (the same on each), by the async one's state.
struct DuringTheJob {
  bool reweight = false, move = false;
  bool zero =
      false;  ///< a loop closure taken to weight 0 (out of the structure), an older one back
};

/// Replays the walk into an inline and an async smoother side by side; after every update
/// where the async one has swapped its job in and started none since, their estimates agree to
/// 1e-8 in the tangent.
template <class G>
void expectSwapEqualsInline(unsigned seed, const SmootherOptions& async_options,
                            DuringTheJob during = {}) {
  std::vector<G> truth;
  const auto by_pose = randomWalk<G>(300, 60, seed, &truth);
  IncrementalSmoother<G> in(inlineOptions()), as(async_options);
  in.addFixedPose(G());
  as.addFixedPose(G());
  std::mt19937 rng(seed);
  int swaps = 0, starts = 0, compared = 0, reweighted = 0, moved = 0, zeroed = 0, readmitted = 0;
  int catch_ups = 0;
  std::vector<int> at_zero;
  bool consistent = true;  // no job in flight since the last swap
  for (size_t k = 1; k < by_pose.size(); ++k) {
    const auto& odo = by_pose[k].front();
    const G guess = in.estimate(odo.i).compose(odo.measurement);
    in.addPose(guess);
    as.addPose(guess);
    for (const auto& e : by_pose[k]) {
      in.addFactor(e);
      as.addFactor(e);
    }
    if (as.relinearizationPending()) {
      if (during.reweight) {  // an old factor and one queued now
        const int f = std::uniform_int_distribution<int>(0, as.numFactors() - 1)(rng);
        const double w = std::uniform_real_distribution<double>(0.2, 0.9)(rng);
        in.setFactorWeight(f, w);
        as.setFactorWeight(f, w);
        in.setFactorWeight(as.numFactors(), 0.7);
        as.setFactorWeight(as.numFactors(), 0.7);
        ++reweighted;
      }
      if (during.zero) {  // a loop closure out of the structure; the oldest one out back in
        const auto& fs = as.factors();
        int f = std::uniform_int_distribution<int>(0, as.numFactors() - 1)(rng);
        for (int tries = 0; tries < as.numFactors(); ++tries, f = (f + 1) % as.numFactors())
          if (fs[f].arity() == 2 && std::abs(fs[f].key(0) - fs[f].key(1)) > 1 &&
              fs[f].inlierWeight() > 0)
            break;
        if (fs[f].arity() == 2 && std::abs(fs[f].key(0) - fs[f].key(1)) > 1 &&
            fs[f].inlierWeight() > 0) {
          in.setFactorWeight(f, 0);
          as.setFactorWeight(f, 0);
          at_zero.push_back(f);
          ++zeroed;
        }
        if (at_zero.size() > 2) {
          in.setFactorWeight(at_zero.front(), 1);
          as.setFactorWeight(at_zero.front(), 1);
          at_zero.erase(at_zero.begin());
          ++readmitted;
        }
      }
      if (during.move && k % 3 == 0) {  // the last poses, rigidly
        typename G::Tangent tau = G::Tangent::Constant(0.002);
        const G T = G::Exp(tau);
        std::vector<int> last;
        for (int v = static_cast<int>(k) - 15; v <= static_cast<int>(k); ++v)
          if (v > 0) last.push_back(v);
        in.transformPoses(last, T);
        as.transformPoses(last, T);
        ++moved;
      }
    }
    in.update();
    const UpdateStats st = as.update();
    ASSERT_EQ(as.numFactors(), in.numFactors()) << "update " << k;
    swaps += st.async_swapped;
    starts += st.async_started;
    catch_ups += st.async_catch_up_started;
    if (st.async_swapped) {
      EXPECT_GT(st.variables_relinearized, 0) << "update " << k;
      consistent = true;
    }
    if (st.async_started) consistent = false;
    if (!consistent) continue;
    int worst = -1;
    const double d = tangentDistance(in.estimate(), as.estimate(), &worst);
    ASSERT_LT(d, 1e-8) << "update " << k << ", pose " << worst << " (swaps so far " << swaps << ")";
    ++compared;
  }
  as.checkInvariants();
  EXPECT_GT(starts, 5);
  EXPECT_GE(swaps, starts - 1);  // the last one may still be in flight
  EXPECT_GT(compared, 50);
  if (async_options.async.catch_up == AsyncCatchUp::kInBackground) {
    // Every job has its catch-up; chained ones add more.
    EXPECT_GE(catch_ups, swaps);
    if (async_options.async.catch_up_max_factors > 0) {
      EXPECT_GT(catch_ups, swaps + swaps / 2);
    }
  }
  if (during.reweight) {
    EXPECT_GT(reweighted, 5);
  }
  if (during.move) {
    EXPECT_GT(moved, 3);
  }
  if (during.zero) {
    EXPECT_GT(zeroed, 5);
    EXPECT_GT(readmitted, 3);
  }
}

SmootherOptions onSwap(SmootherOptions o) {
  o.async.catch_up = AsyncCatchUp::kOnSwap;
  return o;
}

// The default, AsyncCatchUp::kInBackground (the catch-up's own job folds in what arrived during
// the job), and kOnSwap (the swap's update does).
TEST(AsyncRelinearization, SwapEqualsRelinearizingAtTheSnapshot2D) {
  expectSwapEqualsInline<SE2>(11, asyncOptions(true, 5));
  expectSwapEqualsInline<SE2>(12, asyncOptions(true, 3));
  expectSwapEqualsInline<SE2>(13, onSwap(asyncOptions(true, 5)));
}

TEST(AsyncRelinearization, SwapEqualsRelinearizingAtTheSnapshot3D) {
  expectSwapEqualsInline<SE3>(21, asyncOptions(true, 5));
  expectSwapEqualsInline<SE3>(22, asyncOptions(true, 3));
  expectSwapEqualsInline<SE3>(23, onSwap(asyncOptions(true, 5)));
}

// AsyncRelinearizationOptions::catch_up_max_factors: a catch-up whose swap would fold in more
// than that hands its tree to another one (up to catch_up_max_rounds); the estimates after the
// swap are the same.
SmootherOptions chainedCatchUps(SmootherOptions o) {
  o.async.catch_up_max_factors = 1;
  o.async.catch_up_max_rounds = 3;
  return o;
}

TEST(AsyncRelinearization, ChainedCatchUpsEqualRelinearizingAtTheSnapshot) {
  expectSwapEqualsInline<SE2>(14, chainedCatchUps(asyncOptions(true, 5)));
  expectSwapEqualsInline<SE3>(24, chainedCatchUps(asyncOptions(true, 3)));
  expectSwapEqualsInline<SE2>(36, chainedCatchUps(asyncOptions(true, 5)), {true, true});
  expectSwapEqualsInline<SE3>(37, chainedCatchUps(asyncOptions(true, 5)), {false, false, true});
  expectSwapEqualsInline<SE3>(44, chainedCatchUps(asyncOptions(false, 5)));
}

// Factors reweighted and poses moved while the job runs are folded in at the swap.
TEST(AsyncRelinearization, ReweightsAndMovesDuringTheJobAreFoldedIn) {
  expectSwapEqualsInline<SE2>(31, asyncOptions(true, 5), {true, true});
  expectSwapEqualsInline<SE3>(32, asyncOptions(true, 5), {true, true});
  expectSwapEqualsInline<SE2>(35, onSwap(asyncOptions(true, 5)), {true, true});
}

// Loop closures taken to weight 0 while the job runs leave the job's structure at the swap, and
// closures at weight 0 in the snapshot come back into it: the same estimates as inline.
TEST(AsyncRelinearization, ClosuresOutAndBackDuringTheJobAreFoldedIn) {
  expectSwapEqualsInline<SE2>(33, asyncOptions(true, 5), {false, false, true});
  expectSwapEqualsInline<SE3>(34, asyncOptions(true, 3), {false, false, true});
}

// The job on its background thread, the swap at the 5th update after the snapshot (which waits
// for it): the same estimates.
TEST(AsyncRelinearization, BackgroundThreadSwapsAtTheGivenUpdate) {
  expectSwapEqualsInline<SE2>(41, asyncOptions(false, 5));
  expectSwapEqualsInline<SE3>(42, asyncOptions(false, 5));
  expectSwapEqualsInline<SE3>(43, onSwap(asyncOptions(false, 5)));
}

// While the second core is taken (a batch refinement), every check relinearises inline: bit for
// bit the inline path.
TEST(AsyncRelinearization, SecondCoreBusyRelinearizesInline) {
  std::vector<SE2> truth;
  const auto by_pose = randomWalk<SE2>(200, 40, 51, &truth);
  IncrementalSmoother2 in(inlineOptions()), as(asyncOptions(false, 0));
  as.setSecondCoreBusy(true);
  in.addFixedPose(SE2());
  as.addFixedPose(SE2());
  int relinearized = 0;
  for (size_t k = 1; k < by_pose.size(); ++k) {
    const auto& odo = by_pose[k].front();
    in.addPose(in.estimate(odo.i).compose(odo.measurement));
    as.addPose(in.estimate(odo.i).compose(odo.measurement));
    for (const auto& e : by_pose[k]) {
      in.addFactor(e);
      as.addFactor(e);
    }
    relinearized += in.update().variables_relinearized;
    const UpdateStats st = as.update();
    ASSERT_EQ(st.async_started, 0);
    ASSERT_FALSE(as.relinearizationPending());
    const auto a = in.estimate(), b = as.estimate();
    for (size_t v = 0; v < a.size(); ++v) {
      ASSERT_EQ(a[v].translation(), b[v].translation()) << "update " << k << ", pose " << v;
      ASSERT_EQ(a[v].rotation(), b[v].rotation()) << "update " << k << ", pose " << v;
    }
  }
  EXPECT_GT(relinearized, 0);
}

// A smoother copied mid-job waits for the job and swaps it in as the original does; one
// destroyed mid-job waits for its thread (a crash or a leak shows under the sanitizers).
TEST(AsyncRelinearization, CopiedOrDestroyedMidJob) {
  std::vector<SE3> truth;
  const auto by_pose = randomWalk<SE3>(400, 80, 61, &truth);
  int destroyed_pending = 0;
  for (int round = 0; round < 3; ++round) {
    auto s = std::make_unique<IncrementalSmoother3>(asyncOptions(false, 4 + round));
    s->addFixedPose(SE3());
    std::unique_ptr<IncrementalSmoother3> copy;
    size_t copied_at = 0;
    for (size_t k = 1; k < by_pose.size(); ++k) {
      const auto& odo = by_pose[k].front();
      for (IncrementalSmoother3* t : {s.get(), copy.get()}) {
        if (!t) continue;
        t->addPose(s->estimate(odo.i).compose(odo.measurement));
        for (const auto& e : by_pose[k]) t->addFactor(e);
      }
      const UpdateStats st = s->update();
      if (copy) {
        const UpdateStats cs = copy->update();
        ASSERT_EQ(cs.async_swapped, st.async_swapped) << "update " << k;
        const auto a = s->estimate(), b = copy->estimate();
        for (size_t v = 0; v < a.size(); ++v)
          ASSERT_EQ(a[v].translation(), b[v].translation()) << "update " << k << ", pose " << v;
        if (st.async_swapped) break;  // the copy swapped the job it was copied with
      } else if (st.async_started && k > 100 && round == 0) {
        copy = std::make_unique<IncrementalSmoother3>(*s);
        copied_at = k;
        ASSERT_TRUE(copy->relinearizationPending());
      } else if (st.async_started && k > 150) {
        ASSERT_TRUE(s->relinearizationPending());
        ++destroyed_pending;
        break;  // destroyed with its job in flight
      }
    }
    if (round == 0) {
      EXPECT_GT(copied_at, 0u);
    }
    s.reset();
  }
  EXPECT_EQ(destroyed_pending, 2);
}

// Without the hooks the swap comes whenever the job is done: every update keeps the tree's
// invariants and every edge, and the final relinearisation ends where the inline one does
// (also with jobs that iterate Gauss–Newton on their snapshot).
template <class G>
void expectFreeRunningEndsAtTheInlineOptimum(unsigned seed, int job_iterations) {
  std::vector<G> truth;
  const auto by_pose = randomWalk<G>(300, 60, seed, &truth);
  SmootherOptions o;
  o.relinearize = RelinearizationMode::kAsync;
  o.async.min_variables = 1;
  o.async.job_iterations = job_iterations;
  IncrementalSmoother<G> in, as(o);
  in.addFixedPose(G());
  as.addFixedPose(G());
  int starts = 0;
  for (size_t k = 1; k < by_pose.size(); ++k) {
    const auto& odo = by_pose[k].front();
    in.addPose(in.estimate(odo.i).compose(odo.measurement));
    as.addPose(as.estimate(odo.i).compose(odo.measurement));
    for (const auto& e : by_pose[k]) {
      in.addFactor(e);
      as.addFactor(e);
    }
    in.update();
    starts += as.update().async_started;
    ASSERT_NO_THROW(as.checkInvariants()) << "update " << k;
  }
  EXPECT_GT(starts, 0);
  EXPECT_EQ(as.numFactors(), in.numFactors());
  in.relinearizeAll();
  as.relinearizeAll();
  EXPECT_FALSE(as.relinearizationPending());
  EXPECT_NEAR(as.objective(), in.objective(), 1e-5 * in.objective());
}

TEST(AsyncRelinearization, FreeRunningEndsAtTheInlineOptimum) {
  expectFreeRunningEndsAtTheInlineOptimum<SE2>(71, 1);
  expectFreeRunningEndsAtTheInlineOptimum<SE2>(72, 4);
  expectFreeRunningEndsAtTheInlineOptimum<SE3>(73, 4);
}

// AsyncRelinearizationOptions::job_iterations: the job steps every pose by Gauss–Newton and
// re-eliminates; the tree and Δ it hands over are those of one elimination at its last Θ, whose
// F is no higher than one full step from the snapshot's; one iteration is the plain job.
template <class G>
void expectJobIterationsStepTheWholeGraph(unsigned seed) {
  std::vector<G> truth;
  const auto by_pose = randomWalk<G>(150, 40, seed, &truth);
  bayestree::RelinearizationSnapshot<G> s;
  s.theta.push_back(G());
  s.fixed.push_back(1);
  for (size_t k = 1; k < by_pose.size(); ++k) {
    const auto& odo = by_pose[k].front();
    s.theta.push_back(s.theta[odo.i].compose(odo.measurement));  // odometry: far from optimal
    s.fixed.push_back(0);
    for (const auto& e : by_pose[k]) s.factors.push_back(e);
  }
  s.nested_dissection_min = 1 << 30;
  const auto F = [&](const std::vector<G>& theta) {
    double f = 0;
    for (const auto& e : s.factors) f += e.cost(theta);
    return f;
  };
  const auto stepped = [&](const std::vector<G>& theta, const std::vector<typename G::Tangent>& d) {
    std::vector<G> out = theta;
    for (size_t v = 1; v < out.size(); ++v) out[v] = theta[v].retract(d[v]);
    return out;
  };
  const auto once = bayestree::relinearizeSnapshot(s);
  EXPECT_EQ(once.iterations, 1);
  EXPECT_TRUE(once.theta.empty());
  s.iterations = 4;
  const auto iterated = bayestree::relinearizeSnapshot(s);
  ASSERT_GE(iterated.iterations, 2);
  EXPECT_LE(iterated.iterations, 4);
  ASSERT_EQ(iterated.theta.size(), s.theta.size());
  EXPECT_LE(F(iterated.theta), F(stepped(s.theta, once.delta)) * (1 + 1e-12));
  EXPECT_LT(F(stepped(iterated.theta, iterated.delta)), F(s.theta));
  // Its Δ is one elimination's at its Θ.
  bayestree::RelinearizationSnapshot<G> at_theta = s;
  at_theta.theta = iterated.theta;
  at_theta.iterations = 1;
  const auto again = bayestree::relinearizeSnapshot(at_theta);
  for (size_t v = 0; v < s.theta.size(); ++v)
    ASSERT_LT((again.delta[v] - iterated.delta[v]).template lpNorm<Eigen::Infinity>(), 1e-9)
        << "pose " << v;
  EXPECT_EQ(iterated.cliques, again.cliques);
}

// After a swap of an iterated job's tree, the smoother's Δ is the Gauss–Newton step of its
// factors at its linearisation point (the tree was linearised at the job's last Θ, which the
// smoother took), as after every update of the inline path; also with factors reweighted and
// poses moved while the job and its catch-up are in flight.
template <class G>
void expectIteratedSwapIsTheStepAtItsPoint(unsigned seed, AsyncCatchUp catch_up, bool changes) {
  std::vector<G> truth;
  const auto by_pose = randomWalk<G>(300, 60, seed, &truth);
  SmootherOptions o = asyncOptions(true, changes ? 4 : 0);
  o.async.job_iterations = 4;
  o.async.catch_up = catch_up;
  IncrementalSmoother<G> as(o);
  as.addFixedPose(G());
  std::mt19937 rng(seed);
  int checked = 0, reweighted = 0, moved = 0;
  for (size_t k = 1; k < by_pose.size(); ++k) {
    const auto& odo = by_pose[k].front();
    as.addPose(as.estimate(odo.i).compose(odo.measurement));
    for (const auto& e : by_pose[k]) as.addFactor(e);
    if (changes && as.relinearizationPending()) {
      const int f = std::uniform_int_distribution<int>(0, as.numFactors() - 1)(rng);
      as.setFactorWeight(f, std::uniform_real_distribution<double>(0.2, 0.9)(rng));
      ++reweighted;
      if (k % 3 == 0) {  // the last poses, rigidly
        std::vector<int> last;
        for (int v = static_cast<int>(k) - 15; v <= static_cast<int>(k); ++v)
          if (v > 0) last.push_back(v);
        as.transformPoses(last, G::Exp(G::Tangent::Constant(0.002)));
        ++moved;
      }
    }
    const UpdateStats st = as.update();
    ASSERT_NO_THROW(as.checkInvariants()) << "update " << k;
    if (!st.async_swapped || as.relinearizationPending()) continue;
    bayestree::RelinearizationSnapshot<G> here;
    here.theta = as.linearizationPoint();
    for (int v = 0; v < as.numPoses(); ++v) here.fixed.push_back(as.isFixed(v) ? 1 : 0);
    here.factors = as.factors();
    here.nested_dissection_min = 1 << 30;
    const auto step = bayestree::relinearizeSnapshot(here);
    for (int v = 0; v < as.numPoses(); ++v)
      ASSERT_LT((step.delta[v] - as.delta()[v]).template lpNorm<Eigen::Infinity>(), 1e-8)
          << "update " << k << ", pose " << v;
    ++checked;
  }
  EXPECT_GT(checked, 3);
  if (changes) {
    EXPECT_GT(reweighted, 5);
    EXPECT_GT(moved, 2);
  }
}

TEST(AsyncRelinearization, IteratedSwapIsTheStepAtItsPoint) {
  expectIteratedSwapIsTheStepAtItsPoint<SE2>(83, AsyncCatchUp::kOnSwap, false);
  expectIteratedSwapIsTheStepAtItsPoint<SE3>(84, AsyncCatchUp::kOnSwap, false);
  expectIteratedSwapIsTheStepAtItsPoint<SE2>(85, AsyncCatchUp::kInBackground, true);
  expectIteratedSwapIsTheStepAtItsPoint<SE3>(86, AsyncCatchUp::kInBackground, true);
  expectIteratedSwapIsTheStepAtItsPoint<SE3>(87, AsyncCatchUp::kOnSwap, true);
}

TEST(AsyncRelinearization, JobIterationsStepTheWholeGraph) {
  expectJobIterationsStepTheWholeGraph<SE2>(81);
  expectJobIterationsStepTheWholeGraph<SE3>(82);
}

// AsyncRelinearizationOptions::reorder_in_background: a decayed ordering is re-ordered by a job
// (a snapshot with an empty M: the same linearisation point, a fresh ordering) instead of a
// batch update. With nothing ever relinearised (β past any step) the linear system is the same
// on every path, so after every update the estimate is the inline one's (which re-orders by
// batch updates) to rounding; every job is a re-ordering, and the update path runs few or no
// batch updates of its own.
template <class G>
void expectBackgroundReorderEqualsInline(unsigned seed, int poses, int swap_after) {
  std::vector<G> truth;
  const auto by_pose = randomWalk<G>(poses, poses / 4, seed, &truth);
  SmootherOptions in_options = inlineOptions();
  in_options.relinearize_threshold_translation = 1e9;
  in_options.relinearize_threshold_rotation = 1e9;
  in_options.batch.reorder_decay = 1.2;  // re-orderings are frequent
  SmootherOptions as_options = in_options;
  as_options.relinearize = RelinearizationMode::kAsync;
  as_options.async.synchronous = swap_after == 0;
  as_options.async.swap_after_updates = swap_after;
  SmootherOptions off_options = as_options;
  off_options.async.reorder_in_background = false;
  IncrementalSmoother<G> in(in_options), as(as_options), off(off_options);
  for (auto* s : {&in, &as, &off}) s->addFixedPose(G());
  int inline_batches = 0, async_batches = 0, off_batches = 0, starts = 0, swaps = 0, off_starts = 0;
  for (size_t k = 1; k < by_pose.size(); ++k) {
    const auto& odo = by_pose[k].front();
    const G guess = in.estimate(odo.i).compose(odo.measurement);
    for (auto* s : {&in, &as, &off}) {
      s->addPose(guess);
      for (const auto& e : by_pose[k]) s->addFactor(e);
    }
    inline_batches += in.update().batch_reeliminations;
    const UpdateStats st = as.update();
    async_batches += st.batch_reeliminations;
    starts += st.async_started;
    swaps += st.async_swapped;
    EXPECT_EQ(st.variables_relinearized, 0) << "update " << k;
    const UpdateStats off_st = off.update();
    off_batches += off_st.batch_reeliminations;
    off_starts += off_st.async_started;
    int worst = -1;
    ASSERT_LT(tangentDistance(in.estimate(), as.estimate(), &worst), 1e-8)
        << "update " << k << ", pose " << worst;
    ASSERT_NO_THROW(as.checkInvariants()) << "update " << k;
  }
  EXPECT_GE(inline_batches, 2);
  EXPECT_GE(starts, 2);
  EXPECT_GE(swaps, starts - 1);
  EXPECT_LT(async_batches, inline_batches)
      << async_batches << " batch updates against " << inline_batches << " inline";
  // Off: no job (nothing to relinearise), the re-orderings batch updates as inline. (Their
  // counts need not be equal: nested-dissection orderings were seen to differ from run to run
  // while a background job of `as` runs one too; with nested dissection off they did not.)
  EXPECT_EQ(off_starts, 0);
  EXPECT_GE(off_batches, 2);
}

// AsyncRelinearizationOptions::reorder_decay: re-ordering jobs are asked for at their own,
// sooner decay, below the inline bound; the estimate is the same linear system either way.
TEST(AsyncRelinearization, ReorderingJobsComeAtTheirOwnDecay) {
  std::vector<SE2> truth;
  const auto by_pose = randomWalk<SE2>(1500, 375, 85, &truth);
  SmootherOptions late_options = inlineOptions();
  late_options.relinearize_threshold_translation = 1e9;
  late_options.relinearize_threshold_rotation = 1e9;
  late_options.batch.reorder_decay = 3;
  late_options.relinearize = RelinearizationMode::kAsync;
  late_options.async.synchronous = true;
  late_options.async.reorder_decay = 3;
  SmootherOptions soon_options = late_options;
  soon_options.async.reorder_decay = 1.2;
  IncrementalSmoother<SE2> late(late_options), soon(soon_options);
  for (auto* s : {&late, &soon}) s->addFixedPose(SE2());
  int late_starts = 0, soon_starts = 0;
  for (size_t k = 1; k < by_pose.size(); ++k) {
    const auto& odo = by_pose[k].front();
    const SE2 guess = late.estimate(odo.i).compose(odo.measurement);
    for (auto* s : {&late, &soon}) {
      s->addPose(guess);
      for (const auto& e : by_pose[k]) s->addFactor(e);
    }
    late_starts += late.update().async_started;
    soon_starts += soon.update().async_started;
    int worst = -1;
    ASSERT_LT(tangentDistance(late.estimate(), soon.estimate(), &worst), 1e-8)
        << "update " << k << ", pose " << worst;
  }
  EXPECT_GE(soon_starts, 2);
  EXPECT_GT(soon_starts, late_starts)
      << soon_starts << " jobs at decay 1.2, " << late_starts << " at 3";
}

TEST(AsyncRelinearization, DecayedOrderingIsReorderedByAJob2D) {
  expectBackgroundReorderEqualsInline<SE2>(81, 1500, 0);
  expectBackgroundReorderEqualsInline<SE2>(82, 1500, 3);
}
TEST(AsyncRelinearization, DecayedOrderingIsReorderedByAJob3D) {
  expectBackgroundReorderEqualsInline<SE3>(83, 400, 0);
  expectBackgroundReorderEqualsInline<SE3>(84, 400, 3);
}

}  // namespace
}  // namespace arbor
