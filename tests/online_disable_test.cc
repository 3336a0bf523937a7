// Taking an edge back (OnlineSmoother::disableEdge / enableEdge): a disabled edge has weight 0
// from the next update on, so the smoother ends where a replay without it ends; enabling it
// again ends where the replay with it ends; refusals (unknown id, no such edge, already
// disabled or enabled, a bridge) change nothing; snapshot() leaves disabled edges out and
// reseed() keeps them disabled; an edge accepted into a disabled pair enters disabled.
#include <cmath>
#include <random>
#include <vector>

#include <gtest/gtest.h>

#include "arbor_slam/bayestree/online_smoother.h"
#include "arbor_slam/core/batch_solver.h"

namespace arbor {
namespace {

template <class G>
struct Measured {
  Key from, to;
  G z;
  typename RelativePoseEdge<G>::Matrix omega;
};

template <class G>
typename RelativePoseEdge<G>::Matrix information() {
  typename RelativePoseEdge<G>::Matrix m = RelativePoseEdge<G>::Matrix::Zero();
  for (int k = 0; k < G::kDoF; ++k) m(k, k) = k < G::kDim ? 100.0 : 1000.0;
  return m;
}

/// One step of a circle of 20 poses (3D: climbing a little and rolling), so pose k revisits pose
/// k − 20.
template <class G>
G circleStep() {
  typename G::Tangent t = G::Tangent::Zero();
  t(0) = 1.0;
  t(G::kDoF - 1) = 2 * M_PI / 20;
  if constexpr (G::kDim == 3) {
    t(2) = 0.05;
    t(3) = 0.02;
  }
  return G::Exp(t);
}

/// Ids 100 + k. Odometry (k − 1, k) and closures (k − 20, k) for k ≥ 20, noisy; and, when
/// `false_closure`, a wrong closure 105 → 130 (1 m and 0.2 rad off) right after pose 30's
/// edges. `*false_index` is its position in the stream.
template <class G>
std::vector<Measured<G>> loopStream(int n, unsigned seed, bool false_closure = false,
                                    int* false_index = nullptr) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> noise(0.0, 0.01);
  std::vector<G> truth(n, G::Identity());
  for (int k = 1; k < n; ++k) truth[k] = truth[k - 1].compose(circleStep<G>());
  auto z = [&](int a, int b) {
    typename G::Tangent t;
    for (int k = 0; k < G::kDoF; ++k) t(k) = noise(rng);
    return truth[a].inverse().compose(truth[b]).compose(G::Exp(t));
  };
  std::vector<Measured<G>> out;
  for (int k = 1; k < n; ++k) {
    out.push_back({100 + k - 1, 100 + k, z(k - 1, k), information<G>()});
    if (k >= 20) out.push_back({100 + k - 20, 100 + k, z(k - 20, k), information<G>()});
    if (false_closure && k == 30) {
      typename G::Tangent wrong = G::Tangent::Zero();
      wrong(0) = 1.0;
      wrong(G::kDoF - 1) = 0.2;
      if (false_index) *false_index = static_cast<int>(out.size());
      out.push_back({105, 130, truth[5].inverse().compose(truth[30]).compose(G::Exp(wrong)),
                     information<G>()});
    }
  }
  return out;
}

template <class G>
OnlineSmootherOptions<G> converging() {
  OnlineSmootherOptions<G> o;
  o.smoother.finalize_relative_tolerance = 1e-14;
  o.smoother.finalize_max_iterations = 100;
  return o;
}

/// Feeds edges [first, last) one update each, skipping `skip`.
template <class G>
void feed(OnlineSmoother<G>* s, const std::vector<Measured<G>>& edges, size_t first, size_t last,
          int skip = -1) {
  for (size_t k = first; k < last; ++k) {
    if (static_cast<int>(k) == skip) continue;
    const Measured<G>& m = edges[k];
    ASSERT_EQ(s->addEdge(m.from, m.to, m.z, m.omega).status, EdgeStatus::kAccepted);
    s->update();
  }
}

template <class G>
double maxDifference(const OnlineSmoother<G>& a, const OnlineSmoother<G>& b) {
  const auto xa = a.estimates(), xb = b.estimates();
  EXPECT_EQ(xa.size(), xb.size());
  double d = 0;
  for (const auto& [id, x] : xa) d = std::max(d, x.localCoordinates(xb.at(id)).norm());
  return d;
}

/// The factors of s that are disabled: each at weight 0.
template <class G>
int disabledFactors(const OnlineSmoother<G>& s) {
  int n = 0;
  for (int f = 0; f < s.smoother().numFactors(); ++f) {
    if (!s.factorDisabled(f)) continue;
    EXPECT_EQ(s.smoother().factors()[f].inlierWeight(), 0.0) << "factor " << f;
    ++n;
  }
  return n;
}

// A wrong closure taken back ten updates after it arrived: finalize ends where a replay that
// never had it ends.
template <class G>
void expectDisableEqualsReplayWithout(unsigned seed) {
  int bad = -1;
  const auto edges = loopStream<G>(50, seed, true, &bad);
  OnlineSmoother<G> live(converging<G>());
  feed(&live, edges, 0, bad + 10);
  const EdgeSwitchResult r = live.disableEdge(130, 105);  // either direction names the pair
  ASSERT_TRUE(r.applied()) << r.reason;
  // F over the true edges at the estimate the wrong closure had pulled away, against a replay
  // of the same edges without it.
  const double F_polluted = live.objective();
  OnlineSmoother<G> prefix(converging<G>());
  feed(&prefix, edges, 0, bad + 10, bad);
  EXPECT_GT(F_polluted, 2 * prefix.objective()) << prefix.objective();
  EXPECT_EQ(r.edges, 1);
  EXPECT_NE(r.reason.find("105"), std::string::npos) << r.reason;
  feed(&live, edges, bad + 10, edges.size());
  live.finalize();
  live.smoother().checkInvariants();

  OnlineSmoother<G> replay(converging<G>());
  feed(&replay, edges, 0, edges.size(), bad);
  replay.finalize();

  EXPECT_LT(maxDifference(live, replay), 1e-6);
  const double F = replay.smoother().objective();
  EXPECT_NEAR(live.objective(), F, 1e-8 * F);
  EXPECT_GT(live.smoother().objective(), F + 1.0);  // still held, at weight 0: its error shows
  EXPECT_EQ(live.stats().edges_disabled, 1);
  EXPECT_EQ(live.stats().pairs_disabled, 1);
  EXPECT_EQ(disabledFactors(live), 1);
}

TEST(OnlineDisable, DisableThenFinalizeEqualsReplayWithoutTheEdge2D) {
  expectDisableEqualsReplayWithout<SE2>(1);
}
TEST(OnlineDisable, DisableThenFinalizeEqualsReplayWithoutTheEdge3D) {
  expectDisableEqualsReplayWithout<SE3>(2);
}

// A true closure disabled and enabled again ten updates later: finalize ends where the replay
// with it ends; while disabled, a finalize ends where the replay without it ends.
template <class G>
void expectEnableEqualsReplayWith(unsigned seed) {
  const auto edges = loopStream<G>(50, seed);
  // The closure 110 → 130 (edge index: after pose 30's odometry).
  int closure = -1;
  for (size_t k = 0; k < edges.size(); ++k)
    if (edges[k].from == 110 && edges[k].to == 130) closure = static_cast<int>(k);
  ASSERT_GE(closure, 0);
  OnlineSmoother<G> live(converging<G>());
  feed(&live, edges, 0, closure + 5);
  ASSERT_TRUE(live.disableEdge(110, 130).applied());
  feed(&live, edges, closure + 5, closure + 15);
  OnlineSmoother<G> disabled = live;
  disabled.finalize();
  OnlineSmoother<G> without(converging<G>());
  feed(&without, edges, 0, closure + 15, closure);
  without.finalize();
  EXPECT_LT(maxDifference(disabled, without), 1e-6);

  const EdgeSwitchResult r = live.enableEdge(130, 110);
  ASSERT_TRUE(r.applied()) << r.reason;
  EXPECT_EQ(live.stats().edges_disabled, 0);
  feed(&live, edges, closure + 15, edges.size());
  live.finalize();
  live.smoother().checkInvariants();
  OnlineSmoother<G> with(converging<G>());
  feed(&with, edges, 0, edges.size());
  with.finalize();
  EXPECT_LT(maxDifference(live, with), 1e-6);
  const double F = with.smoother().objective();
  EXPECT_NEAR(live.objective(), F, 1e-8 * F);
  EXPECT_EQ(live.objective(), live.smoother().objective());  // nothing disabled
  for (const auto& f : live.smoother().factors()) EXPECT_EQ(f.inlierWeight(), 1.0);
}

TEST(OnlineDisable, EnableAgainEqualsReplayWithTheEdge2D) { expectEnableEqualsReplayWith<SE2>(3); }
TEST(OnlineDisable, EnableAgainEqualsReplayWithTheEdge3D) { expectEnableEqualsReplayWith<SE3>(4); }

// Every refusal names the reason and changes nothing: the next update gives bit for bit the
// estimate of a copy that was never asked.
TEST(OnlineDisable, RefusalsChangeNothing) {
  const auto edges = loopStream<SE2>(40, 5);
  OnlineSmoother2 s;
  feed(&s, edges, 0, edges.size());
  ASSERT_TRUE(s.disableEdge(115, 135).applied());
  s.update();
  OnlineSmoother2 untouched = s;

  struct Case {
    EdgeSwitchResult result;
    EdgeSwitchStatus expected;
    const char* names;  // what the reason must mention
  };
  const std::vector<Case> cases = {
      {s.disableEdge(100, 99999), EdgeSwitchStatus::kUnknownPose, "99999"},
      {s.enableEdge(-3, 100), EdgeSwitchStatus::kUnknownPose, "-3"},
      {s.disableEdge(100, 107), EdgeSwitchStatus::kNoSuchEdge, "100 - 107"},
      {s.disableEdge(104, 104), EdgeSwitchStatus::kNoSuchEdge, "104"},
      {s.disableEdge(135, 115), EdgeSwitchStatus::kAlreadyDisabled, "115"},
      {s.enableEdge(100, 101), EdgeSwitchStatus::kAlreadyEnabled, "101"},
  };
  for (const Case& c : cases) {
    EXPECT_EQ(c.result.status, c.expected) << c.result.reason;
    EXPECT_NE(c.result.reason.find(c.names), std::string::npos) << c.result.reason;
  }
  s.update();
  untouched.update();
  EXPECT_EQ(maxDifference(s, untouched), 0.0);
  EXPECT_EQ(s.stats().edges_disabled, 1);
  EXPECT_EQ(disabledFactors(s), 1);

  // Pose 139, the last, hangs on its odometry edge 138 → 139 and its closure 119 → 139 only:
  // with the closure disabled, the odometry edge is a bridge.
  ASSERT_TRUE(s.disableEdge(119, 139).applied());
  s.update();
  untouched = s;
  const EdgeSwitchResult bridge = s.disableEdge(138, 139);
  EXPECT_EQ(bridge.status, EdgeSwitchStatus::kBridge) << bridge.reason;
  EXPECT_NE(bridge.reason.find("bridge"), std::string::npos) << bridge.reason;
  s.update();
  untouched.update();
  EXPECT_EQ(maxDifference(s, untouched), 0.0);
  EXPECT_EQ(s.stats().edges_disabled, 2);
  // With the closure enabled again the odometry edge is no bridge any more, and then the
  // closure is.
  ASSERT_TRUE(s.enableEdge(119, 139).applied());
  EXPECT_TRUE(s.disableEdge(138, 139).applied());
  EXPECT_EQ(s.disableEdge(119, 139).status, EdgeSwitchStatus::kBridge);
}

// A chain without closures: every edge is a bridge.
TEST(OnlineDisable, EveryEdgeOfATreeIsABridge) {
  const auto edges = loopStream<SE2>(15, 6);
  OnlineSmoother2 s;
  feed(&s, edges, 0, edges.size());
  for (const auto& m : edges) {
    const EdgeSwitchResult r = s.disableEdge(m.from, m.to);
    EXPECT_EQ(r.status, EdgeSwitchStatus::kBridge) << r.reason;
  }
  EXPECT_EQ(s.stats().edges_disabled, 0);
}

// A closure disabled before the update that takes it in enters at weight 0; a later edge
// between the same two poses (another measurement) enters disabled too, and enabling the pair
// brings back both.
TEST(OnlineDisable, QueuedAndLaterEdgesOfADisabledPairEnterDisabled) {
  int bad = -1;
  const auto edges = loopStream<SE2>(45, 7, true, &bad);
  OnlineSmoother2 live(converging<SE2>());
  feed(&live, edges, 0, bad);
  const auto& m = edges[bad];
  ASSERT_EQ(live.addEdge(m.from, m.to, m.z, m.omega).status, EdgeStatus::kAccepted);
  ASSERT_TRUE(live.disableEdge(m.from, m.to).applied());  // still queued
  live.update();
  const SE2 other = m.z.compose(SE2(0.3, 0, 0));
  ASSERT_EQ(live.addEdge(m.to, m.from, other.inverse(), m.omega).status, EdgeStatus::kAccepted);
  feed(&live, edges, bad + 1, edges.size());
  EXPECT_EQ(live.stats().edges_disabled, 2);
  EXPECT_EQ(disabledFactors(live), 2);
  live.finalize();
  OnlineSmoother2 replay(converging<SE2>());
  feed(&replay, edges, 0, edges.size(), bad);
  replay.finalize();
  EXPECT_LT(maxDifference(live, replay), 1e-6);
  const EdgeSwitchResult r = live.enableEdge(m.from, m.to);
  ASSERT_TRUE(r.applied());
  EXPECT_EQ(r.edges, 2);
  live.update();
  EXPECT_EQ(disabledFactors(live), 0);
  for (const auto& f : live.smoother().factors()) EXPECT_EQ(f.inlierWeight(), 1.0);
}

// The odometry edge that would bring a new pose in, disabled while queued together with the
// pose's closure: the closure introduces the pose (a weight-0 factor never does), no clique is
// singular, and the run ends where the replay without the odometry edge ends.
TEST(OnlineDisable, AQueuedCreatorEdgeDisabledLeavesThePoseToItsOtherEdge) {
  const auto edges = loopStream<SE2>(45, 9);
  int odometry = -1;
  for (size_t k = 0; k < edges.size(); ++k)
    if (edges[k].from == 129 && edges[k].to == 130) odometry = static_cast<int>(k);
  ASSERT_GE(odometry, 0);
  ASSERT_EQ(edges[odometry + 1].from, 110);  // its closure 110 → 130 comes right after
  OnlineSmoother2 live(converging<SE2>());
  feed(&live, edges, 0, odometry);
  for (int k : {odometry, odometry + 1}) {
    const auto& m = edges[k];
    ASSERT_EQ(live.addEdge(m.from, m.to, m.z, m.omega).status, EdgeStatus::kAccepted);
  }
  ASSERT_TRUE(live.disableEdge(129, 130).applied());
  const UpdateStats u = live.update();
  EXPECT_EQ(u.indeterminate_cliques, 0);
  live.smoother().checkInvariants();
  feed(&live, edges, odometry + 2, edges.size());
  live.finalize();
  OnlineSmoother2 replay(converging<SE2>());
  feed(&replay, edges, 0, edges.size(), odometry);
  replay.finalize();
  EXPECT_LT(maxDifference(live, replay), 1e-6);
}

// snapshot() is the batch problem without the disabled edge; a reseed from its optimum keeps
// the edge disabled and gives the replay's optimum.
TEST(OnlineDisable, SnapshotLeavesDisabledEdgesOutAndReseedKeepsThem) {
  int bad = -1;
  const auto edges = loopStream<SE3>(45, 8, true, &bad);
  OnlineSmoother3 live(converging<SE3>());
  feed(&live, edges, 0, edges.size());
  ASSERT_TRUE(live.disableEdge(105, 130).applied());
  live.update();
  const PoseGraph<SE3> snap = live.snapshot();
  EXPECT_EQ(snap.numEdges(), static_cast<int>(edges.size()) - 1);
  for (const auto& e : snap.edges) {
    const Key a = snap.ids[e.i], b = snap.ids[e.j];
    EXPECT_FALSE(std::min(a, b) == 105 && std::max(a, b) == 130);
  }
  std::vector<SE3> optimum = snap.poses;
  BatchOptions lm;
  lm.relative_tolerance = 1e-14;
  solveBatch(snap, &optimum, lm);
  const ReseedResult r = live.reseed(optimum, /*only_if_lower=*/true);
  EXPECT_TRUE(r.applied) << "F before " << r.F_before << ", rebuilt " << r.F_rebuilt;
  EXPECT_NEAR(r.F_rebuilt, objective(snap, optimum), 1e-6 * objective(snap, optimum));
  live.smoother().checkInvariants();
  EXPECT_EQ(disabledFactors(live), 1);
  EXPECT_EQ(live.stats().edges_disabled, 1);
  EXPECT_EQ(live.disableEdge(105, 130).status, EdgeSwitchStatus::kAlreadyDisabled);
  // The reseeded smoother goes on without the edge: finalize = the replay without it.
  live.finalize();
  OnlineSmoother3 replay(converging<SE3>());
  feed(&replay, edges, 0, edges.size(), bad);
  replay.finalize();
  EXPECT_LT(maxDifference(live, replay), 1e-6);
  // And the pair can still be enabled after the rebuild renumbered the factors.
  ASSERT_TRUE(live.enableEdge(105, 130).applied());
  live.update();
  EXPECT_EQ(disabledFactors(live), 0);
  for (const auto& f : live.smoother().factors()) EXPECT_EQ(f.inlierWeight(), 1.0);
}

}  // namespace
}  // namespace arbor
