// A random walk with loop closures, for the tests that replay one into the smoother update by
// update (the batch switch, asynchronous relinearisation, cached factors), and that replay.
#pragma once

#include <random>
#include <vector>

#include "arbor_slam/bayestree/incremental_smoother.h"
#include "arbor_slam/core/pose_graph.h"
#include "arbor_slam/tests/random_graphs.h"

namespace arbor::testing {

/// A random walk of n poses with odometry and `loops` loop closures to random older poses (a
/// loop at pose k is added with it), noisy measurements; the edges grouped per new pose.
template <class G>
std::vector<std::vector<RelativePoseEdge<G>>> randomWalk(int n, int loops, unsigned seed,
                                                         std::vector<G>* truth) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> normal(0.0, 1.0);
  truth->assign(1, G());
  for (int k = 1; k < n; ++k) {
    typename G::Tangent step = isotropicNoise<G>(rng, 0.3);
    step(0) += 1.0;
    truth->push_back(truth->back().compose(G::Exp(step)));
  }
  const auto omega = diagonalInformation<G>(100.0, 400.0);
  auto measured = [&](int i, int j) {
    return (*truth)[i].between((*truth)[j]).compose(G::Exp(isotropicNoise<G>(rng, 0.05)));
  };
  std::vector<std::vector<RelativePoseEdge<G>>> by_pose(n);
  for (int k = 1; k < n; ++k)
    by_pose[k].push_back(RelativePoseEdge<G>::make(k - 1, k, measured(k - 1, k), omega));
  std::uniform_int_distribution<int> pick(2, n - 1);
  for (int l = 0; l < loops; ++l) {
    const int j = pick(rng);
    const int i = std::uniform_int_distribution<int>(0, j - 2)(rng);
    by_pose[j].push_back(RelativePoseEdge<G>::make(i, j, measured(i, j), omega));
  }
  return by_pose;
}

/// Feeds a walk's pose k (dead-reckoned from its odometry) and its edges, then update(), for
/// every k after the fixed first pose; `check(smoother, stats)` after each update.
template <class G, class Check>
void replayWalk(const std::vector<std::vector<RelativePoseEdge<G>>>& by_pose,
                IncrementalSmoother<G>* s, Check check) {
  s->addFixedPose(G());
  for (size_t k = 1; k < by_pose.size(); ++k) {
    const auto& odo = by_pose[k].front();
    s->addPose(s->estimate(odo.i).compose(odo.measurement));
    for (const auto& e : by_pose[k]) s->addFactor(e);
    check(*s, s->update());
  }
}

}  // namespace arbor::testing
