// Replaying a graph with priors (tools/cli/replay_runner.h, replay_order.h): each pose's priors
// reach the online smoother right after the edge that makes the pose known; the replay ends at
// batch LM's F on the same problem, whether priors anchor the graph or an anchor pose does.
#include <random>
#include <vector>

#include <gtest/gtest.h>

#include "arbor_slam/core/batch_solver.h"
#include "arbor_slam/tools/cli/replay_runner.h"

namespace arbor {
namespace {

template <class G>
PoseGraph<G> gpsLoop(int n, unsigned seed, bool pose_prior, int gps_every) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> noise(0.0, 1.0);
  auto tangent = [&](double t, double r) {
    typename G::Tangent x;
    for (int k = 0; k < G::kDoF; ++k) x(k) = noise(rng) * (k < G::kDim ? t : r);
    return x;
  };
  std::vector<G> truth(n, G::Exp(tangent(30.0, 1.0)));
  for (int k = 1; k < n; ++k) {
    typename G::Tangent s = tangent(0.2, 0.15);
    s(0) += 1.0;
    truth[k] = truth[k - 1].compose(G::Exp(s));
  }
  PoseGraph<G> g;
  typename RelativePoseEdge<G>::Matrix omega = RelativePoseEdge<G>::Matrix::Identity() * 100;
  for (int k = 0; k < n; ++k) {
    g.ids.push_back(k);
    g.index[k] = k;
    g.poses.push_back(G::Identity());
  }
  auto edge = [&](int i, int j) {
    g.edges.push_back(RelativePoseEdge<G>::make(
        i, j, truth[i].between(truth[j]).compose(G::Exp(tangent(0.05, 0.02))), omega));
  };
  for (int k = 1; k < n; ++k) edge(k - 1, k);
  for (int k = 12; k < n; k += 9) edge(k - 10, k);
  if (pose_prior) g.pose_priors.push_back(PosePriorFactor<G>::make(0, truth[0], omega));
  for (int k = gps_every; k < n; k += gps_every) {
    typename G::Translation p = truth[k].translation();
    for (int d = 0; d < G::kDim; ++d) p(d) += 0.3 * noise(rng);
    g.position_priors.push_back(PositionPriorFactor<G>::make(
        k, p, Eigen::Matrix<double, G::kDim, G::kDim>::Identity() * 4.0));
  }
  return g;
}

template <class G>
void expectReplayMatchesBatch(bool pose_prior, int gps_every, unsigned seed) {
  const PoseGraph<G> graph = gpsLoop<G>(80, seed, pose_prior, gps_every);
  cli::ReplaySettings settings;
  settings.batch = true;
  const cli::ReplayResult<G> r = cli::runReplay(graph, settings);
  EXPECT_EQ(r.rejected, 0);
  EXPECT_NE(r.batch.termination, Termination::kDiverged) << r.batch.message;
  // The batch LM runs from the replay's estimate: it can only confirm it.
  EXPECT_NEAR(r.F_final, r.batch.F_final, 1e-6 * r.batch.F_final);
  // And LM from far away (odometry in the first pose's frame) reaches the same F.
  std::vector<G> far(graph.poses.size());
  for (size_t k = 1; k < far.size(); ++k)
    far[k] = far[k - 1].compose(graph.edges[k - 1].measurement);
  BatchOptions o;
  o.relative_tolerance = 1e-12;
  o.max_iterations = 500;
  const BatchSummary batch = solveBatch(graph, &far, o);
  EXPECT_NEAR(r.F_final, batch.F_final, 1e-6 * batch.F_final);
}

TEST(ReplayPriors, PosePriorAndGps2D) { expectReplayMatchesBatch<SE2>(true, 10, 1); }
TEST(ReplayPriors, GpsOnly2D) { expectReplayMatchesBatch<SE2>(false, 10, 2); }
TEST(ReplayPriors, PosePriorAndGps3D) { expectReplayMatchesBatch<SE3>(true, 10, 3); }
TEST(ReplayPriors, GpsOnly3D) { expectReplayMatchesBatch<SE3>(false, 10, 4); }

}  // namespace
}  // namespace arbor
