// OnlineSmoother::snapshot() and reseed() (issue 5, "The loop"): after reseeding with the batch
// optimum of a snapshot the estimate is that optimum and F its F; updates continue; poses
// outside the values move rigidly with their creator; bad values throw naming the id.
#include <cmath>
#include <limits>
#include <map>
#include <random>
#include <stdexcept>
#include <vector>

#include <gtest/gtest.h>

#include "arbor_slam/bayestree/online_smoother.h"
#include "arbor_slam/core/batch_solver.h"

namespace arbor {
namespace {

const Eigen::Matrix3d kI3 = Eigen::Matrix3d::Identity();

// A noisy 2D loop trajectory with loop closures, as (from, to, z) triples in arrival order.
struct Measured {
  Key from, to;
  SE2 z;
};

std::vector<Measured> noisyLoop(int n, double sigma, unsigned seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> noise(0, sigma);
  std::vector<SE2> truth(n);
  for (int k = 1; k < n; ++k) truth[k] = truth[k - 1].compose(SE2(1, 0, 2 * M_PI / 20));
  auto z = [&](int a, int b) {
    return truth[a].between(truth[b]).compose(SE2(noise(rng), noise(rng), noise(rng)));
  };
  std::vector<Measured> out;
  for (int k = 1; k < n; ++k) {
    out.push_back({100 + k - 1, 100 + k, z(k - 1, k)});
    if (k >= 20) out.push_back({100 + k - 20, 100 + k, z(k - 20, k)});
  }
  return out;
}

double maxDifference(const std::vector<SE2>& a, const std::vector<SE2>& b) {
  double d = 0;
  for (size_t k = 0; k < a.size(); ++k) d = std::max(d, a[k].localCoordinates(b[k]).norm());
  return d;
}

TEST(OnlineReseed, SnapshotHoldsThePosesAndEdgesOfTheLastUpdate) {
  OnlineSmoother<SE2> s;
  EXPECT_EQ(s.snapshot().numPoses(), 0);
  s.addEdge(5, 6, SE2(1, 0, 0), kI3);
  s.addEdge(6, 7, SE2(1, 0, 0), kI3);
  s.update();
  s.addEdge(7, 8, SE2(1, 0, 0), kI3);  // not yet taken in by an update
  const PoseGraph<SE2> snap = s.snapshot();
  ASSERT_EQ(snap.numPoses(), 3);
  EXPECT_EQ(snap.ids, (std::vector<Key>{5, 6, 7}));
  EXPECT_EQ(snap.index.at(7), 2);
  EXPECT_EQ(snap.numEdges(), 2);
  EXPECT_EQ(snap.fixed, std::vector<int>{0});
  EXPECT_NEAR(objective(snap, snap.poses), s.smoother().objective(), 1e-12);
  s.update();
  EXPECT_EQ(s.snapshot().numPoses(), 4);
}

TEST(OnlineReseed, BatchOptimumBecomesTheEstimateAndUpdatesContinue) {
  const std::vector<Measured> edges = noisyLoop(80, 0.05, 3);
  const size_t half = edges.size() / 2;
  OnlineSmoother<SE2> s;
  for (size_t k = 0; k < half; ++k) {
    s.addEdge(edges[k].from, edges[k].to, edges[k].z, kI3);
    s.update();
  }
  PoseGraph<SE2> snap = s.snapshot();
  std::vector<SE2> optimum = snap.poses;
  BatchOptions lm;
  lm.relative_tolerance = 1e-12;
  const BatchSummary b = solveBatch(snap, &optimum, lm);
  const double F_batch = objective(snap, optimum);
  ASSERT_LT(F_batch, s.smoother().objective());
  // Hand the optimum over by id, moved by a rigid transform: reseed undoes it at the gauge.
  const SE2 moved(3, -2, 0.7);
  std::map<Key, SE2> values;
  for (int k = 0; k < snap.numPoses(); ++k) values[snap.ids[k]] = moved.compose(optimum[k]);
  const ReseedResult r = s.reseed(values);
  EXPECT_TRUE(r.applied);
  EXPECT_GT(r.stats.time_s, 0.0);
  EXPECT_EQ(r.stats.variables_reeliminated, snap.numPoses() - 1);  // the whole tree
  EXPECT_NEAR(r.F_rebuilt, F_batch, 1e-9 * F_batch);
  EXPECT_GT(r.F_before, r.F_rebuilt);
  EXPECT_EQ(s.stats().reseeds, 1);
  s.smoother().checkInvariants();
  EXPECT_TRUE(s.smoother().isFixed(0));
  EXPECT_NEAR(s.smoother().objective(), F_batch, 1e-9 * F_batch) << b.iterations;
  std::vector<SE2> now;
  for (Key id : snap.ids) now.push_back(s.estimate(id));
  EXPECT_LT(maxDifference(now, optimum), 1e-6);
  EXPECT_EQ(s.estimate(snap.ids[0]).x(), 0.0);  // the gauge stays where it was

  // Further edges and updates work from the new linearisation point.
  for (size_t k = half; k < edges.size(); ++k) {
    EXPECT_EQ(s.addEdge(edges[k].from, edges[k].to, edges[k].z, kI3).status, EdgeStatus::kAccepted);
    s.update();
  }
  s.smoother().checkInvariants();
  s.finalize();
  OnlineSmoother<SE2> plain;
  for (const Measured& m : edges) {
    plain.addEdge(m.from, m.to, m.z, kI3);
    plain.update();
  }
  plain.finalize();
  EXPECT_NEAR(s.smoother().objective(), plain.smoother().objective(),
              1e-6 * plain.smoother().objective());
}

TEST(OnlineReseed, PosesOutsideTheValuesMoveWithTheirCreator) {
  OnlineSmoother<SE2> s;
  s.addEdge(0, 1, SE2(1, 0, 0), kI3);
  s.addEdge(1, 2, SE2(1, 0, 0), kI3);
  s.update();
  s.addEdge(2, 3, SE2(0, 1, 0), kI3);  // queued: 3 exists but no update took it in yet
  s.addEdge(9, 3, SE2(1, 0, 0), kI3);  // 9 created from 3 (inverse measurement)
  // Move pose 2 (the creator of 3, hence of 9) by a rotation about pose 1.
  const SE2 new2(1, 1, M_PI / 2);
  const std::vector<SE2> seed = s.seedPoint(std::map<Key, SE2>{{2, new2}});
  ASSERT_EQ(seed.size(), 5u);
  EXPECT_NEAR(seed[2].localCoordinates(new2).norm(), 0, 1e-12);
  const SE2 rel3 = s.estimate(2).between(s.estimate(3));
  EXPECT_NEAR(seed[3].localCoordinates(new2.compose(rel3)).norm(), 0, 1e-12);
  const SE2 rel9 = s.estimate(3).between(s.estimate(9));
  EXPECT_NEAR(seed[4].localCoordinates(seed[3].compose(rel9)).norm(), 0, 1e-12);
  EXPECT_NEAR(seed[1].localCoordinates(s.estimate(1)).norm(), 0, 1e-12);  // its creator: gauge
  // The queued edges go into the rebuild. Seeded at the exact value of 2 (every measurement is
  // exact), the rebuilt estimate has F = 0.
  s.reseed(std::map<Key, SE2>{{2, SE2(2, 0, 0)}});
  EXPECT_EQ(s.smoother().numFactors(), 4);
  EXPECT_LT(s.smoother().objective(), 1e-20);
  EXPECT_NEAR(s.estimate(9).localCoordinates(SE2(1, 1, 0)).norm(), 0, 1e-12);
  s.smoother().checkInvariants();
  // Dense-prefix form: the same as the map of the first ids.
  EXPECT_EQ(s.seedPoint(std::vector<SE2>{SE2(), SE2(1, 0, 0)}).size(), 5u);
}

TEST(OnlineReseed, OnlyIfLowerKeepsTheSmootherWhenTheSeedIsWorse) {
  const std::vector<Measured> edges = noisyLoop(60, 0.05, 5);
  OnlineSmoother<SE2> s;
  for (const Measured& m : edges) {
    s.addEdge(m.from, m.to, m.z, kI3);
    s.update();
  }
  const std::map<Key, SE2> current = s.estimates();
  const double F = s.smoother().objective();
  // A seed with every pose turned by 0.3 rad about itself: far worse than the estimate.
  std::map<Key, SE2> bad;
  for (const auto& [id, x] : current) bad[id] = x.compose(SE2(0, 0, id == 100 ? 0.0 : 0.3));
  const ReseedResult kept = s.reseed(bad, /*only_if_lower=*/true);
  EXPECT_FALSE(kept.applied);
  EXPECT_GT(kept.F_rebuilt, kept.F_before);
  EXPECT_NEAR(kept.F_before, F, 1e-12 * F);
  EXPECT_EQ(s.smoother().objective(), F);  // untouched
  EXPECT_EQ(s.stats().reseeds, 0);
  // The same seed without the check is applied (and is worse).
  const ReseedResult forced = s.reseed(bad);
  EXPECT_TRUE(forced.applied);
  EXPECT_GT(s.smoother().objective(), F);
  EXPECT_EQ(s.stats().reseeds, 1);
}

TEST(OnlineReseed, BadValuesThrowNamingTheIdAndChangeNothing) {
  OnlineSmoother<SE2> s;
  s.addEdge(10, 11, SE2(1, 0, 0), kI3);
  s.update();
  const double F = s.smoother().objective();
  try {
    s.reseed(std::map<Key, SE2>{{42, SE2()}});
    ADD_FAILURE() << "no throw";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("42"), std::string::npos) << e.what();
  }
  const double nan = std::numeric_limits<double>::quiet_NaN();
  try {
    s.reseed(std::map<Key, SE2>{{11, SE2(nan, 0, 0)}});
    ADD_FAILURE() << "no throw";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("11"), std::string::npos) << e.what();
  }
  EXPECT_THROW(s.reseed(std::vector<SE2>(3)), std::invalid_argument);
  EXPECT_EQ(s.stats().reseeds, 0);
  EXPECT_EQ(s.smoother().objective(), F);
  EXPECT_EQ(s.addEdge(11, 12, SE2(1, 0, 0), kI3).status, EdgeStatus::kAccepted);
  s.update();
  EXPECT_NEAR(s.estimate(12).x(), 2, 1e-9);
}

TEST(OnlineReseed, Works3D) {
  OnlineSmoother<SE3> s;
  const Eigen::Matrix<double, 6, 6> I6 = Eigen::Matrix<double, 6, 6>::Identity();
  SE3::Tangent t;
  t << 1, 0, 0, 0, 0, 0.3;
  const SE3 step = SE3::Exp(t);
  for (int k = 0; k < 10; ++k) s.addEdge(k, k + 1, step, I6);
  s.addEdge(0, 10, step.compose(step), I6);  // inconsistent: F > 0
  s.update();
  PoseGraph<SE3> snap = s.snapshot();
  std::vector<SE3> optimum = snap.poses;
  BatchOptions lm;
  lm.relative_tolerance = 1e-12;
  solveBatch(snap, &optimum, lm);
  s.reseed(optimum);
  EXPECT_NEAR(s.smoother().objective(), objective(snap, optimum), 1e-9 * objective(snap, optimum));
  s.smoother().checkInvariants();
}

}  // namespace
}  // namespace arbor
