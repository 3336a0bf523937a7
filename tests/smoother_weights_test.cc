// The smoother's weight seam (IncrementalSmoother::setFactorWeight): a factor enters the linear
// system scaled by √w, a new weight is a relinearisation of that factor, w = 0 is the factor's
// absence.
#include <cmath>
#include <random>
#include <vector>

#include <gtest/gtest.h>
#include <Eigen/Cholesky>
#include <Eigen/Core>

#include "arbor_slam/bayestree/incremental_smoother.h"
#include "arbor_slam/core/factor.h"
#include "arbor_slam/tests/random_graphs.h"

namespace arbor {
namespace {

using testing::diagonalInformation;
using testing::isotropicNoise;

/// A noisy trajectory of n poses with odometry and loop closures every 7 poses back to the
/// start region, plus one wrong closure (the last factor): off by `error` metres and a fifth of
/// that in radians.
template <class G>
std::vector<Factor<G>> loopGraph(int n, unsigned seed, std::vector<G>* truth, double error = 5.0) {
  std::mt19937 rng(seed);
  truth->assign(n, G::Identity());
  for (int k = 1; k < n; ++k) {
    typename G::Tangent t = isotropicNoise<G>(rng, 0.2);
    t(0) += 1.0;
    (*truth)[k] = (*truth)[k - 1].compose(G::Exp(t));
  }
  const auto omega = diagonalInformation<G>(50.0, 400.0);
  std::vector<Factor<G>> fs;
  auto edge = [&](int i, int j, double sigma) {
    const G z =
        (*truth)[i].inverse().compose((*truth)[j]).compose(G::Exp(isotropicNoise<G>(rng, sigma)));
    fs.emplace_back(RelativePoseEdge<G>::make(i, j, z, omega));
  };
  for (int k = 1; k < n; ++k) edge(k - 1, k, 0.02);
  for (int k = 9; k < n; k += 7) edge(k - 9, k, 0.02);
  typename G::Tangent wrong = G::Tangent::Zero();
  wrong(0) = error;
  wrong(G::kDoF - 1) = 0.2 * error;
  const G z_bad = G::Exp(wrong);
  fs.emplace_back(RelativePoseEdge<G>::make(2, n - 3, z_bad, omega));
  return fs;
}

/// A smoother fed the factors one pose at a time (dead-reckoned initial values), then
/// converged.
/// Options that let relinearizeAll run Gauss–Newton to convergence (a wrong closure makes it
/// converge linearly, not quadratically).
SmootherOptions converging() {
  SmootherOptions o;
  o.finalize_relative_tolerance = 1e-14;
  o.finalize_max_iterations = 100;
  return o;
}

template <class G>
IncrementalSmoother<G> smootherOf(const std::vector<Factor<G>>& fs, int n,
                                  SmootherOptions options = converging()) {
  IncrementalSmoother<G> s(options);
  s.addFixedPose(G::Identity());
  std::vector<G> x(1, G::Identity());
  for (int k = 1; k < n; ++k) {
    for (const Factor<G>& f : fs) {
      const auto* e = f.relativePose();
      if (e && e->j == k && e->i == k - 1) {
        x.push_back(x[k - 1].compose(e->measurement));
        s.addPose(x[k]);
      }
    }
    for (const Factor<G>& f : fs)
      if (std::max(f.key(0), f.key(1)) == k) s.addFactor(f);
    s.update();
  }
  return s;
}

/// The smoother's index of the factor between i and j (smootherOf adds factors in order of
/// their later pose, not in the order given).
template <class G>
int indexOf(const IncrementalSmoother<G>& s, int i, int j) {
  for (int f = 0; f < s.numFactors(); ++f)
    if (s.factors()[f].arity() == 2 && s.factors()[f].key(0) == i && s.factors()[f].key(1) == j)
      return f;
  return -1;
}

template <class G>
void converge(IncrementalSmoother<G>* s) {
  s->relinearizeAll();
}

template <class G>
double maxDifference(const std::vector<G>& a, const std::vector<G>& b) {
  double d = 0;
  for (size_t v = 0; v < a.size(); ++v) d = std::max(d, a[v].localCoordinates(b[v]).norm());
  return d;
}

// w = 0 on the wrong closure after it was eliminated equals never having added it (a closure
// wrong by 1 m: Gauss–Newton from either state reaches the same minimum).
template <class G>
void expectZeroWeightIsAbsence(unsigned seed) {
  constexpr int n = 40;
  std::vector<G> truth;
  const std::vector<Factor<G>> fs = loopGraph<G>(n, seed, &truth, 1.0);
  IncrementalSmoother<G> with = smootherOf(fs, n);
  const double F_with = with.objective();
  const int bad = indexOf(with, 2, n - 3);
  ASSERT_GE(bad, 0);
  with.setFactorWeight(bad, 0.0);
  with.update();
  with.checkInvariants();
  converge(&with);
  with.checkInvariants();
  std::vector<Factor<G>> clean(fs.begin(), fs.end() - 1);
  IncrementalSmoother<G> without = smootherOf(clean, n);
  converge(&without);
  EXPECT_LT(maxDifference(with.estimate(), without.estimate()), 1e-6);
  EXPECT_NEAR(with.weightedObjective(), without.objective(), 1e-9 * without.objective());
  // The weighted objective leaves the wrong closure out; the plain objective still counts it.
  EXPECT_GT(with.objective(), with.weightedObjective() + 1.0);
  EXPECT_LT(with.weightedObjective(), 0.1 * F_with);
  // And back: w = 1 again returns to the estimate with the closure in full.
  IncrementalSmoother<G> full = smootherOf(fs, n);
  converge(&full);
  with.setFactorWeight(bad, 1.0);
  with.update();
  converge(&with);
  with.checkInvariants();
  EXPECT_LT(maxDifference(with.estimate(), full.estimate()), 1e-6);
}

TEST(SmootherWeights, ZeroWeightEqualsTheFactorsAbsence2D) { expectZeroWeightIsAbsence<SE2>(1); }
TEST(SmootherWeights, ZeroWeightEqualsTheFactorsAbsence3D) { expectZeroWeightIsAbsence<SE3>(2); }

/// Dense Gauss–Newton step of Σ w‖Σ A τ + r‖² at x (every pose but 0 free).
template <class G>
std::vector<typename G::Tangent> denseWeightedStep(const std::vector<Factor<G>>& fs,
                                                   const std::vector<G>& x) {
  constexpr int D = G::kDoF;
  const int n = static_cast<int>(x.size()) - 1;
  Eigen::MatrixXd H = Eigen::MatrixXd::Zero(n * D, n * D);
  Eigen::VectorXd g = Eigen::VectorXd::Zero(n * D);
  for (const Factor<G>& f : fs) {
    typename Factor<G>::Linearization L;
    f.linearizeWeighted(x, &L);
    for (int a = 0; a < f.arity(); ++a) {
      const int va = f.key(a) - 1;
      if (va < 0) continue;
      g.segment<D>(va * D) -= L.A[a].transpose() * L.r;
      for (int b = 0; b < f.arity(); ++b) {
        const int vb = f.key(b) - 1;
        if (vb >= 0) H.block<D, D>(va * D, vb * D) += L.A[a].transpose() * L.A[b];
      }
    }
  }
  const Eigen::VectorXd tau = H.llt().solve(g);
  std::vector<typename G::Tangent> out(n + 1, G::Tangent::Zero());
  for (int v = 0; v < n; ++v) out[v + 1] = tau.segment<D>(v * D);
  return out;
}

// With nothing relinearised, Δ after a weight change is the exact Gauss–Newton step of the
// weighted system at θ: the Bayes tree holds the √w-scaled factor, not the old one.
template <class G>
void expectExactWeightedStep(unsigned seed) {
  constexpr int n = 30;
  std::vector<G> truth;
  const std::vector<Factor<G>> fs = loopGraph<G>(n, seed, &truth);
  SmootherOptions o;
  o.relinearize_skip = 1000000;  // θ stays where each pose was added
  o.full_backsubstitution = true;
  IncrementalSmoother<G> s = smootherOf(fs, n, o);
  std::vector<Factor<G>> weighted = s.factors();
  const int bad = indexOf(s, 2, n - 3);
  for (int f : {bad, bad - 1, 3}) {
    const double w = f == bad ? 0.01 : 0.5;
    s.setFactorWeight(f, w);
    weighted[f].setInlierWeight(w);
  }
  const UpdateStats st = s.update();
  EXPECT_GT(st.cliques_reeliminated, 0);
  s.checkInvariants();
  const auto expected = denseWeightedStep(weighted, s.linearizationPoint());
  for (int v = 1; v < n; ++v)
    EXPECT_LT((s.delta()[v] - expected[v]).norm(), 1e-8 * (1 + expected[v].norm())) << v;
  double F = 0;
  const std::vector<G> x = s.estimate();
  for (const Factor<G>& f : weighted) F += f.inlierWeight() * f.cost(x);
  EXPECT_NEAR(s.weightedObjective(), F, 1e-12 * F);
}

TEST(SmootherWeights, ExactWeightedGaussNewtonStep2D) { expectExactWeightedStep<SE2>(3); }
TEST(SmootherWeights, ExactWeightedGaussNewtonStep3D) { expectExactWeightedStep<SE3>(4); }

// A factor added with a weight and one reweighted later reach the same estimate.
TEST(SmootherWeights, AddedWithWeightEqualsReweighted) {
  constexpr int n = 30;
  std::vector<SE2> truth;
  std::vector<Factor2> fs = loopGraph<SE2>(n, 5, &truth, 1.0);
  IncrementalSmoother2 later = smootherOf(fs, n);
  later.setFactorWeight(indexOf(later, 2, n - 3), 0.05);
  later.update();
  converge(&later);
  fs.back().setInlierWeight(0.05);
  IncrementalSmoother2 from_start = smootherOf(fs, n);
  converge(&from_start);
  EXPECT_EQ(later.factors()[indexOf(later, 2, n - 3)].inlierWeight(), 0.05);
  EXPECT_LT(maxDifference(later.estimate(), from_start.estimate()), 1e-6);
}

// Unit weights set explicitly change nothing, bit for bit.
TEST(SmootherWeights, UnitWeightsChangeNothing) {
  constexpr int n = 30;
  std::vector<SE3> truth;
  const std::vector<Factor3> fs = loopGraph<SE3>(n, 6, &truth);
  IncrementalSmoother3 a = smootherOf(fs, n);
  IncrementalSmoother3 b = smootherOf(fs, n);
  for (int f = 0; f < b.numFactors(); ++f) b.setFactorWeight(f, 1.0);  // no-op: already 1
  const UpdateStats sa = a.update(), sb = b.update();
  EXPECT_EQ(sa.cliques_reeliminated, sb.cliques_reeliminated);
  for (int v = 0; v < n; ++v)
    EXPECT_EQ(a.estimate(v).translation(), b.estimate(v).translation()) << v;
  EXPECT_EQ(a.objective(), b.weightedObjective());
}

// A queued factor (index numFactors() + k) takes its weight before it enters: the wrong closure
// queued with w = 0 gives exactly the estimate of never adding it, and it is kept at w = 0.
TEST(SmootherWeights, QueuedFactorTakesItsWeightBeforeItEnters) {
  constexpr int n = 30;
  std::vector<SE2> truth;
  const std::vector<Factor2> fs = loopGraph<SE2>(n, 5, &truth, 1.0);
  const std::vector<Factor2> clean(fs.begin(), fs.end() - 1);
  IncrementalSmoother2 with = smootherOf(clean, n);
  IncrementalSmoother2 without = with;
  with.addFactor(fs.back());
  EXPECT_THROW(with.setFactorWeight(with.numFactors() + 1, 0.0), std::invalid_argument);
  with.setFactorWeight(with.numFactors(), 0.0);
  with.update();
  with.checkInvariants();
  ASSERT_EQ(with.numFactors(), without.numFactors() + 1);
  EXPECT_EQ(with.factors().back().inlierWeight(), 0.0);
  converge(&with);
  converge(&without);
  EXPECT_LT(maxDifference(with.estimate(), without.estimate()), 1e-9);
  EXPECT_NEAR(with.weightedObjective(), without.objective(), 1e-9 * without.objective());
  EXPECT_GT(with.objective(), with.weightedObjective() + 1.0);  // the closure is still held
}

/// loopGraph with `extra` more wrong closures (between poses i and n − 1 − i for i = 4, 8, …),
/// all of them (the last 1 + extra factors) at weight `w`.
template <class G>
std::vector<Factor<G>> withWrongClosures(int n, unsigned seed, int extra, double w) {
  std::vector<G> truth;
  std::vector<Factor<G>> fs = loopGraph<G>(n, seed, &truth, 1.0);
  const auto omega = diagonalInformation<G>(50.0, 400.0);
  for (int k = 1; k <= extra; ++k) {
    typename G::Tangent off = G::Tangent::Zero();
    off(0) = 3.0;
    fs.emplace_back(RelativePoseEdge<G>::make(4 * k, n - 1 - 4 * k, G::Exp(off), omega));
  }
  for (size_t f = fs.size() - 1 - extra; f < fs.size(); ++f) fs[f].setInlierWeight(w);
  return fs;
}

// A factor at weight 0 is no part of the elimination: a graph fed with wrong closures at w = 0
// has the Bayes tree of the graph without them — the same cliques, separators and flops — and
// its estimate, bit for bit, at every update.
template <class G>
void expectZeroWeightLeavesTheStructure(unsigned seed) {
  constexpr int n = 60;
  const std::vector<Factor<G>> fs = withWrongClosures<G>(n, seed, 4, 0.0);
  const std::vector<Factor<G>> clean(fs.begin(), fs.end() - 5);
  IncrementalSmoother<G> with = smootherOf(fs, n);
  IncrementalSmoother<G> without = smootherOf(clean, n);
  with.checkInvariants();
  ASSERT_EQ(with.numFactors(), without.numFactors() + 5);
  EXPECT_EQ(with.numCliques(), without.numCliques());
  EXPECT_EQ(with.factorizationFlops(), without.factorizationFlops());
  const TreeMemory a = with.memory(), b = without.memory();
  EXPECT_EQ(a.max_separator_dim, b.max_separator_dim);
  EXPECT_EQ(a.mean_separator_dim, b.mean_separator_dim);
  EXPECT_EQ(a.clique_bytes, b.clique_bytes);
  EXPECT_EQ(maxDifference(with.estimate(), without.estimate()), 0.0);
  // The same after relinearising all (the wrong closures are not relinearised either).
  converge(&with);
  converge(&without);
  EXPECT_EQ(with.numCliques(), without.numCliques());
  EXPECT_EQ(with.factorizationFlops(), without.factorizationFlops());
  EXPECT_EQ(maxDifference(with.estimate(), without.estimate()), 0.0);
  EXPECT_EQ(with.weightedObjective(), without.objective());
  EXPECT_GT(with.objective(), with.weightedObjective() + 1.0);  // they are still held
}

TEST(SmootherWeights, ZeroWeightLeavesTheStructure2D) {
  expectZeroWeightLeavesTheStructure<SE2>(8);
}
TEST(SmootherWeights, ZeroWeightLeavesTheStructure3D) {
  expectZeroWeightLeavesTheStructure<SE3>(9);
}

// A factor re-admitted from weight 0 enters as a new one: w = 0 → 1 on a true closure gives the
// update (fold-in or re-elimination, cliques, flops, estimate bit for bit) of a smoother that
// never had it and gets it added now.
template <class G>
void expectReadmittedEqualsAddedFresh(unsigned seed) {
  constexpr int n = 50;
  std::vector<G> truth;
  std::vector<Factor<G>> fs = loopGraph<G>(n, seed, &truth, 1.0);
  fs.pop_back();                  // the wrong closure: every factor left is true
  Factor<G> closure = fs.back();  // the last closure k − 9 → k
  ASSERT_EQ(closure.key(1) - closure.key(0), 9);
  fs.back().setInlierWeight(0.0);
  IncrementalSmoother<G> readmitted = smootherOf(fs, n);
  fs.pop_back();
  IncrementalSmoother<G> fresh = smootherOf(fs, n);
  const int f = indexOf(readmitted, closure.key(0), closure.key(1));
  ASSERT_GE(f, 0);
  ASSERT_EQ(readmitted.factors()[f].inlierWeight(), 0.0);
  readmitted.setFactorWeight(f, 1.0);
  fresh.addFactor(closure);
  const UpdateStats a = readmitted.update(), b = fresh.update();
  readmitted.checkInvariants();
  EXPECT_EQ(a.cliques_updated, b.cliques_updated);
  EXPECT_EQ(a.cliques_reeliminated, b.cliques_reeliminated);
  EXPECT_EQ(a.cliques_solved, b.cliques_solved);
  EXPECT_EQ(readmitted.numCliques(), fresh.numCliques());
  EXPECT_EQ(readmitted.factorizationFlops(), fresh.factorizationFlops());
  EXPECT_EQ(maxDifference(readmitted.estimate(), fresh.estimate()), 0.0);
  EXPECT_EQ(readmitted.weightedObjective(), fresh.objective());
}

TEST(SmootherWeights, ReadmittedEqualsAddedFresh2D) { expectReadmittedEqualsAddedFresh<SE2>(10); }
TEST(SmootherWeights, ReadmittedEqualsAddedFresh3D) { expectReadmittedEqualsAddedFresh<SE3>(11); }

// Out of the structure and back: w > 0 → 0 re-eliminates the factor's cliques without it (it
// leaves the tree), 0 → w' > 0 before the next update brings it back; the tree stays valid and
// the estimate is that of the weight in force.
TEST(SmootherWeights, OutAndBackBeforeAnUpdate) {
  constexpr int n = 40;
  std::vector<SE2> truth;
  const std::vector<Factor2> fs = loopGraph<SE2>(n, 12, &truth, 1.0);
  IncrementalSmoother2 s = smootherOf(fs, n);
  const int bad = indexOf(s, 2, n - 3);
  s.setFactorWeight(bad, 0.0);
  s.setFactorWeight(bad, 0.5);
  s.update();
  s.checkInvariants();
  converge(&s);
  std::vector<Factor2> half = fs;
  half.back().setInlierWeight(0.5);
  IncrementalSmoother2 ref = smootherOf(half, n);
  converge(&ref);
  EXPECT_LT(maxDifference(s.estimate(), ref.estimate()), 1e-5);
  // Out for good: the tree no longer holds it.
  s.setFactorWeight(bad, 0.0);
  s.update();
  s.checkInvariants();
  converge(&s);
  std::vector<Factor2> clean(fs.begin(), fs.end() - 1);
  IncrementalSmoother2 without = smootherOf(clean, n);
  converge(&without);
  EXPECT_LT(maxDifference(s.estimate(), without.estimate()), 1e-6);
}

TEST(SmootherWeights, BadWeightOrIndexIsRefusedAndChangesNothing) {
  constexpr int n = 20;
  std::vector<SE2> truth;
  const std::vector<Factor2> fs = loopGraph<SE2>(n, 7, &truth);
  IncrementalSmoother2 s = smootherOf(fs, n);
  IncrementalSmoother2 untouched = s;
  EXPECT_THROW(s.setFactorWeight(-1, 0.5), std::invalid_argument);
  EXPECT_THROW(s.setFactorWeight(s.numFactors(), 0.5), std::invalid_argument);
  EXPECT_THROW(s.setFactorWeight(0, std::nan("")), std::invalid_argument);
  EXPECT_THROW(s.setFactorWeight(0, 1.5), std::invalid_argument);
  EXPECT_THROW(s.setFactorWeight(0, -0.1), std::invalid_argument);
  s.update();
  untouched.update();
  EXPECT_EQ(maxDifference(untouched.estimate(), s.estimate()), 0.0);
  for (const Factor2& f : s.factors()) EXPECT_EQ(f.inlierWeight(), 1.0);
}

// SmootherOptions::newest_last: an update that only reweights (no new factor, no new pose) puts
// the reweighted closure's poses last, and with them the newest pose, so the next pose's
// odometry finds it at the top. Without it the reweighting's top is ordered with the closure's
// two poses alone last, the newest pose further down, and the next odometry re-eliminates the
// longer path from its clique up (here 3 cliques against 4 in 2D, 3 against 5 in 3D). The
// estimate is the same either way.
template <class G>
void expectNewestPoseStaysLast(unsigned seed) {
  constexpr int n = 40;
  std::vector<G> truth;
  const std::vector<Factor<G>> fs = loopGraph<G>(n, seed, &truth, 1.0);
  UpdateStats next[2];
  std::vector<G> estimate[2];
  for (const bool newest_last : {true, false}) {
    SmootherOptions options;
    options.newest_last = newest_last;
    IncrementalSmoother<G> s = smootherOf(fs, n, options);
    const int bad = indexOf(s, 2, n - 3);
    ASSERT_GE(bad, 0);
    s.setFactorWeight(bad, 0.0);
    const UpdateStats reweighted = s.update();
    EXPECT_EQ(reweighted.new_variables, 0);
    EXPECT_GT(reweighted.cliques_reeliminated, 0);
    const G z = truth[n - 1].inverse().compose(truth[n - 1]);
    s.addPose(s.estimate()[n - 1].compose(z));
    s.addFactor(RelativePoseEdge<G>::make(n - 1, n, z, diagonalInformation<G>(50.0, 400.0)));
    next[newest_last ? 0 : 1] = s.update();
    s.checkInvariants();
    estimate[newest_last ? 0 : 1] = s.estimate();
  }
  EXPECT_GT(next[1].cliques_reeliminated, next[0].cliques_reeliminated);
  EXPECT_LT(next[0].reelimination_flops, next[1].reelimination_flops);
  EXPECT_LT(maxDifference(estimate[0], estimate[1]), 1e-6);
}

TEST(SmootherWeights, NewestPoseStaysLast2D) { expectNewestPoseStaysLast<SE2>(12); }
TEST(SmootherWeights, NewestPoseStaysLast3D) { expectNewestPoseStaysLast<SE3>(13); }

}  // namespace
}  // namespace arbor
