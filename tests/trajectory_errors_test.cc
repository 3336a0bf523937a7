// `arbor plot`'s metrics (tools/cli/trajectory_errors.h) on trajectories whose ATE and RPE are
// known by hand, and reading trajectories back (io/trajectory_reader.h).
#include <cmath>
#include <random>
#include <sstream>
#include <stdexcept>

#include <gtest/gtest.h>
#include <Eigen/Geometry>

#include "arbor_slam/io/pose_graph_file.h"
#include "arbor_slam/io/trajectory_reader.h"
#include "arbor_slam/io/trajectory_writer.h"
#include "arbor_slam/tools/cli/trajectory_errors.h"
#include "random_graphs.h"

namespace arbor::cli {
namespace {

// A random walk of n 3D poses stamped 100 + k/10 s.
Trajectory walk(int n, unsigned seed) {
  std::mt19937 rng(seed);
  Trajectory t;
  SE3 x;
  for (int k = 0; k < n; ++k) {
    t.stamps.push_back(100 + 0.1 * k);
    t.poses.push_back(x);
    SE3::Tangent step = testing::isotropicNoise<SE3>(rng, 0.3);
    step(0) += 1.0;
    x = x.compose(SE3::Exp(step));
  }
  return t;
}

TEST(TrajectoryErrors, AnEstimateAgainstItselfIsZero) {
  const Trajectory t = walk(50, 1);
  const TrajectoryErrors e = trajectoryErrors(t, t);
  EXPECT_EQ(e.associated, 50);
  EXPECT_EQ(e.rpe_pairs, 49);
  EXPECT_LT(e.ate_rmse, 1e-12);
  EXPECT_EQ(e.rpe_rmse, 0.0);
}

// A copy moved rigidly as a whole (rotated and shifted) has no error after the alignment, and no
// relative error at all; the alignment found is the inverse of the move.
TEST(TrajectoryErrors, ARigidlyMovedCopyIsZeroAfterTheAlignment) {
  const Trajectory reference = walk(50, 2);
  const SE3 move(Eigen::Quaterniond(Eigen::AngleAxisd(0.7, Eigen::Vector3d(1, 2, 3).normalized())),
                 Eigen::Vector3d(5, -3, 2));
  Trajectory estimate = reference;
  for (SE3& x : estimate.poses) x = move.compose(x);
  const TrajectoryErrors e = trajectoryErrors(estimate, reference);
  EXPECT_LT(e.ate_rmse, 1e-9);
  EXPECT_LT(e.rpe_rmse, 1e-9);
  EXPECT_LT((e.alignment.compose(move).translation()).norm(), 1e-9);
  // Unaligned, the move would show: the alignment is what makes it zero.
  double unaligned = 0;
  for (size_t k = 0; k < reference.poses.size(); ++k)
    unaligned += (estimate.poses[k].translation() - reference.poses[k].translation()).norm();
  EXPECT_GT(unaligned / 50, 1.0);
}

// The unit square's corners at identity rotation; the estimate lifts them by +ε, −ε, +ε, −ε
// along z. The lifts are uncorrelated with x and y and average zero, so the best rigid move is
// the identity and every position is ε off: ATE = ε. Each step's relative translation is off by
// 2ε along z: RPE = 2ε.
TEST(TrajectoryErrors, APerturbedSquareHasTheErrorsComputedByHand) {
  const double eps = 0.05;
  Trajectory reference, estimate;
  const double corners[4][2] = {{0, 0}, {1, 0}, {1, 1}, {0, 1}};
  for (int k = 0; k < 4; ++k) {
    const Eigen::Vector3d p(corners[k][0], corners[k][1], 0);
    reference.stamps.push_back(k);
    reference.poses.emplace_back(Eigen::Quaterniond::Identity(), p);
    estimate.stamps.push_back(k);
    estimate.poses.emplace_back(Eigen::Quaterniond::Identity(),
                                p + Eigen::Vector3d(0, 0, k % 2 == 0 ? eps : -eps));
  }
  const TrajectoryErrors e = trajectoryErrors(estimate, reference);
  EXPECT_NEAR(e.ate_rmse, eps, 1e-12);
  EXPECT_NEAR(e.ate_max, eps, 1e-12);
  EXPECT_NEAR(e.rpe_rmse, 2 * eps, 1e-12);
  EXPECT_EQ(e.rpe_pairs, 3);
}

// Poses associate with the nearest reference time within max_diff, as evo's t_max_diff.
TEST(TrajectoryErrors, AssociationByNearestTime) {
  Trajectory reference, estimate;
  for (double s : {1.0, 2.0, 3.0, 4.0}) reference.stamps.push_back(s);
  for (double s : {0.5, 1.004, 2.996, 3.5, 4.0}) estimate.stamps.push_back(s);
  reference.poses.resize(4);
  estimate.poses.resize(5);
  const auto pairs = associateByTime(estimate, reference, 0.01);
  const std::vector<std::pair<int, int>> expected = {{1, 0}, {2, 2}, {4, 3}};
  EXPECT_EQ(pairs, expected);
  EXPECT_EQ(associateByTime(estimate, reference, 0.6).size(), 5u);
  Trajectory far = estimate;
  for (double& s : far.stamps) s += 100;
  EXPECT_THROW(trajectoryErrors(far, reference), std::invalid_argument);
}

// What io/trajectory_writer.h writes reads back: TUM exactly, KITTI to rounding of R; a line of
// another shape is refused naming the place.
TEST(TrajectoryReader, ReadsBackTumAndKitti) {
  const Trajectory t = walk(20, 3);
  std::vector<Key> ids;
  for (int k = 0; k < 20; ++k) ids.push_back(k);
  for (TrajectoryFormat format : {TrajectoryFormat::kTum, TrajectoryFormat::kKitti}) {
    std::stringstream text;
    writeTrajectory(text, format, ids, t.poses);
    const Trajectory back = readTrajectory(text, "t");
    ASSERT_EQ(back.poses.size(), 20u);
    for (int k = 0; k < 20; ++k) {
      EXPECT_EQ(back.stamps[k], k);
      EXPECT_LT((back.poses[k].translation() - t.poses[k].translation()).norm(), 1e-12);
      EXPECT_LT(back.poses[k].quaternion().angularDistance(t.poses[k].quaternion()), 1e-9);
    }
  }
  std::istringstream ragged("0 0 0 0 0 0 0 1\n1 0 0 0 0 0 1\n");
  try {
    readTrajectory(ragged, "r.tum");
    ADD_FAILURE() << "a short line was read";
  } catch (const FileError& e) {
    EXPECT_EQ(std::string(e.what()).rfind("r.tum:2: expected 8 fields", 0), 0u) << e.what();
  }
  std::istringstream shear("1 0.5 0 0 0 1 0 0 0 0 1 0\n");
  EXPECT_THROW(readTrajectory(shear, "s.kitti"), FileError);
}

}  // namespace
}  // namespace arbor::cli
