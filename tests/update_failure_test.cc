// An update in which a factor of your own fails (its error function throws, returns NaN or a
// wrong shape) throws FactorError and leaves the smoother exactly as before it
// (IncrementalSmoother::update, docs/library.md "When an update throws"); the updates after it
// give the estimate of a smoother that never saw the failing one. Also OnlineSmoother's update
// (the failing queued factor taken out) and relinearizeAll.
#include <atomic>
#include <cmath>
#include <limits>
#include <memory>
#include <random>
#include <stdexcept>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <Eigen/Core>

#include "arbor_slam/bayestree/incremental_smoother.h"
#include "arbor_slam/bayestree/online_smoother.h"
#include "arbor_slam/core/custom_factor.h"
#include "arbor_slam/core/factor.h"
#include "arbor_slam/core/factor_error.h"
#include "arbor_slam/tests/custom_factor_support.h"

namespace arbor {
namespace {

using testing::diagonalInformation;
using testing::randomPoint;
using testing::randomTangent;
using testing::rangeModel;
using testing::trajectory;

enum class Fail { kNone, kThrow, kNaN, kWrongSize };

// A model that evaluates `inner` unless its switch says to fail.
template <class G>
class Flaky final : public FactorModel<G> {
 public:
  using typename FactorModel<G>::Residual;
  using typename FactorModel<G>::Jacobians;
  Flaky(std::shared_ptr<const FactorModel<G>> inner, std::shared_ptr<std::atomic<int>> fail)
      : inner_(std::move(inner)), fail_(std::move(fail)) {}
  int rows() const override { return inner_->rows(); }
  int arity() const override { return inner_->arity(); }
  std::string name() const override { return "flaky"; }
  void evaluate(const std::array<const G*, 2>& x, Residual* e, Jacobians* J) const override {
    const auto mode = static_cast<Fail>(fail_->load());
    if (mode == Fail::kThrow) throw std::runtime_error("no range today");
    inner_->evaluate(x, e, J);
    if (mode == Fail::kNaN) (*e)(0) = std::numeric_limits<double>::quiet_NaN();
    if (mode == Fail::kWrongSize) e->resize(rows() + 1);
  }

 private:
  std::shared_ptr<const FactorModel<G>> inner_;
  std::shared_ptr<std::atomic<int>> fail_;
};

template <class G>
struct World {
  std::vector<G> truth, start;
  std::vector<std::vector<Factor<G>>> factors_at;  // arriving with pose k
  std::vector<Eigen::Matrix<double, G::kDim, 1>> anchors;
};

template <class G>
World<G> world(int n, unsigned seed) {
  std::mt19937_64 rng(seed);
  World<G> w;
  w.truth = trajectory<G>(n, rng);
  w.factors_at.resize(static_cast<size_t>(n));
  const auto noisy = [&](const G& z) { return z.compose(G::Exp(randomTangent<G>(rng, .05, .02))); };
  const auto omega = diagonalInformation<G>(100, 400);
  std::normal_distribution<double> normal(0.0, 0.1);
  for (int a = 0; a < 3; ++a) w.anchors.push_back(randomPoint<G>(rng, 15));
  w.factors_at[0].push_back(PosePriorFactor<G>::make(0, noisy(w.truth[0]), omega));
  w.start.push_back(noisy(w.truth[0]));
  for (int k = 1; k < n; ++k) {
    auto& at = w.factors_at[static_cast<size_t>(k)];
    const G z = noisy(w.truth[k - 1].between(w.truth[k]));
    at.push_back(RelativePoseEdge<G>::make(k - 1, k, z, omega));
    w.start.push_back(w.start.back().compose(z));
    if (k % 3 == 0) {
      const auto& a = w.anchors[static_cast<size_t>(k / 3 % 3)];
      const double range = (w.truth[k].translation() - a).norm() + normal(rng);
      at.push_back(
          CustomFactor<G>::make(rangeModel<G>(a, range), Eigen::MatrixXd::Constant(1, 1, 25.0), k));
    }
    if (k % 7 == 0 && k > 7)  // a loop closure
      at.push_back(
          RelativePoseEdge<G>::make(k - 7, k, noisy(w.truth[k - 7].between(w.truth[k])), omega));
  }
  return w;
}

// What must not change when an update throws.
template <class G>
struct State {
  std::vector<G> estimate, theta;
  std::vector<typename G::Tangent> delta;
  std::vector<int> updated;
  int factors = 0, cliques = 0;
  double F = 0;
  explicit State(const IncrementalSmoother<G>& s)
      : estimate(s.estimate()),
        theta(s.linearizationPoint()),
        delta(s.delta()),
        updated(s.updatedPoses()),
        factors(s.numFactors()),
        cliques(s.numCliques()),
        F(s.objective()) {}
};

template <class G>
void expectSame(const State<G>& a, const State<G>& b) {
  ASSERT_EQ(a.estimate.size(), b.estimate.size());
  for (size_t v = 0; v < a.estimate.size(); ++v) {
    EXPECT_EQ(a.estimate[v].Log(), b.estimate[v].Log()) << "pose " << v;
    EXPECT_EQ(a.theta[v].Log(), b.theta[v].Log()) << "pose " << v;
    EXPECT_EQ(a.delta[v], b.delta[v]) << "pose " << v;
  }
  EXPECT_EQ(a.updated, b.updated);
  EXPECT_EQ(a.factors, b.factors);
  EXPECT_EQ(a.cliques, b.cliques);
  EXPECT_EQ(a.F, b.F);
}

template <class G>
void expectClose(const IncrementalSmoother<G>& a, const IncrementalSmoother<G>& b,
                 const std::string& when) {
  ASSERT_EQ(a.numPoses(), b.numPoses()) << when;
  ASSERT_EQ(a.numFactors(), b.numFactors()) << when;
  EXPECT_LE(std::abs(a.objective() - b.objective()), 1e-12 * b.objective()) << when;
  for (int v = 0; v < a.numPoses(); ++v)
    EXPECT_LE((a.estimate(v).Log() - b.estimate(v).Log()).cwiseAbs().maxCoeff(), 1e-12)
        << when << ", pose " << v;
}

struct Scenario {
  Fail fail = Fail::kThrow;
  bool existing = false;  // the failing factor is in the graph already (fails relinearised)
  int threads = 2;
  bool relinearize_every_update = false;
};

// Smoother a sees the failing update, b never does; after it, every update of both agrees.
template <class G>
void run(const Scenario& sc, unsigned seed) {
  const int n = 36, bad = 20, added = 11;
  const World<G> w = world<G>(n, seed);
  SmootherOptions o;
  o.threads = sc.threads;
  if (sc.relinearize_every_update || sc.existing) {
    o.relinearize_threshold_translation = 0;
    o.relinearize_threshold_rotation = 0;
    o.relinearize_skip = 1;
  }
  IncrementalSmoother<G> a(o), b(o);
  auto fail_a = std::make_shared<std::atomic<int>>(0);
  auto fail_b = std::make_shared<std::atomic<int>>(0);
  const auto flaky = [&](int k, const std::shared_ptr<std::atomic<int>>& fail) {
    const auto& anchor = w.anchors[0];
    const double range = (w.truth[k].translation() - anchor).norm();
    return CustomFactor<G>::make(std::make_shared<Flaky<G>>(rangeModel<G>(anchor, range), fail),
                                 Eigen::MatrixXd::Constant(1, 1, 25.0), k);
  };
  for (int k = 0; k < n; ++k) {
    for (IncrementalSmoother<G>* s : {&a, &b}) {
      s->addPose(w.start[static_cast<size_t>(k)]);
      for (const auto& f : w.factors_at[static_cast<size_t>(k)]) s->addFactor(f);
    }
    if (sc.existing && k == added) {
      a.addFactor(flaky(k, fail_a));
      b.addFactor(flaky(k, fail_b));
    }
    if (!sc.existing && k == bad) {
      fail_a->store(static_cast<int>(sc.fail));
      a.addFactor(flaky(k - 2, fail_a));  // queued between good ones
      a.addFactor(w.factors_at[static_cast<size_t>(k)][0]);
      b.addFactor(w.factors_at[static_cast<size_t>(k)][0]);
    }
    if (k == bad) {
      const State<G> before(a);  // objective() evaluates the flaky factor too: not failing yet
      if (sc.existing) fail_a->store(static_cast<int>(sc.fail));
      const int queued_index = a.numFactors() + static_cast<int>(w.factors_at[k].size());
      try {
        a.update();
        FAIL() << "the update did not throw";
      } catch (const FactorError& e) {
        const std::string what = e.what();
        EXPECT_NE(what.find("'flaky'"), std::string::npos) << what;
        EXPECT_NE(what.find("t = ("), std::string::npos) << what;
        const char* cause = sc.fail == Fail::kThrow ? "no range today"
                            : sc.fail == Fail::kNaN ? "not finite"
                                                    : "expected 1";
        EXPECT_NE(what.find(cause), std::string::npos) << what;
        if (sc.existing) {
          EXPECT_LT(e.factor(), a.numFactors());
          EXPECT_EQ(a.factors()[e.factor()].name(), "flaky");
        } else {
          EXPECT_EQ(e.factor(), queued_index);
        }
        EXPECT_THROW(e.rethrow_nested(), std::exception);
      }
      if (sc.existing) fail_a->store(0);  // it is fixed: the queue waited
      expectSame(State<G>(a), before);
      a.checkInvariants();
      if (!sc.existing) a.discardQueuedFactor(queued_index);
    }
    a.update();
    b.update();
    a.checkInvariants();
    expectClose(a, b, "update " + std::to_string(k));
  }
  a.relinearizeAll();
  b.relinearizeAll();
  expectClose(a, b, "relinearizeAll");
}

template <class G>
class UpdateFailure : public ::testing::Test {};
using Groups = ::testing::Types<SE2, SE3>;
TYPED_TEST_SUITE(UpdateFailure, Groups);

TYPED_TEST(UpdateFailure, ThrowingNewFactorLeavesTheSmootherAsBefore) {
  run<TypeParam>({Fail::kThrow, false, 2, false}, 1);
  run<TypeParam>({Fail::kThrow, false, 1, true}, 2);
}

TYPED_TEST(UpdateFailure, NonFiniteOrMisshapenNewFactorLeavesTheSmootherAsBefore) {
  run<TypeParam>({Fail::kNaN, false, 2, false}, 3);
  run<TypeParam>({Fail::kWrongSize, false, 2, true}, 4);
}

TYPED_TEST(UpdateFailure, FactorFailingWhenRelinearisedLeavesTheSmootherAsBefore) {
  run<TypeParam>({Fail::kThrow, true, 2, true}, 5);
  run<TypeParam>({Fail::kNaN, true, 1, true}, 6);
}

// A relinearizeAll iteration in which a factor fails is undone: the estimate stays the last
// completed one's, and the smoother goes on.
TEST(UpdateFailure, RelinearizeAllKeepsTheLastCompletedIteration) {
  const World<SE2> w = world<SE2>(24, 7);
  IncrementalSmoother2 s;
  auto fail = std::make_shared<std::atomic<int>>(0);
  for (int k = 0; k < 24; ++k) {
    s.addPose(w.start[static_cast<size_t>(k)]);
    for (const auto& f : w.factors_at[static_cast<size_t>(k)]) s.addFactor(f);
    if (k == 5)
      s.addFactor(CustomFactor<SE2>::make(
          std::make_shared<Flaky<SE2>>(rangeModel<SE2>(w.anchors[1], 3.0), fail),
          Eigen::MatrixXd::Constant(1, 1, 25.0), k));
    s.update();
  }
  const State<SE2> before(s);
  fail->store(static_cast<int>(Fail::kThrow));
  EXPECT_THROW(s.relinearizeAll(), FactorError);
  fail->store(0);
  const State<SE2> after(s);
  for (size_t v = 0; v < before.estimate.size(); ++v)
    EXPECT_EQ(after.estimate[v].Log(), before.estimate[v].Log());
  s.checkInvariants();
  s.relinearizeAll();
  s.checkInvariants();
}

}  // namespace
}  // namespace arbor
