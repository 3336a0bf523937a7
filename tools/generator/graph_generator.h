// Synthetic pose graphs with known ground truth, deterministic by seed:
//  - a 2D Manhattan world in the style of Olson's M3500 (unit steps on a grid, 90° turns,
//    loop closures on revisits);
//  - a 3D sphere in the style of Kümmerle's sphere2500 (rings of poses, closures to the ring
//  below);
//  - a 3D grid random walk in the style of the "Cube" dataset.
// Measurements are the true relative poses perturbed by z = z_true · Exp(n), n ~ N(0, Σ), Σ
// diagonal (NoiseModel's sigmas); the information written is Ω = information_scale · Σ⁻¹ on
// every edge, odometry and loop closures alike: 1 is the truth, below 1 a cautious front end
// (Ω smaller than the noise drawn: χ² at the truth averages information_scale · dof), above 1
// an over-confident one. The initial estimate is the noisy odometry chain. Car-like worlds:
// road_world.h.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "arbor_slam/core/pose_graph.h"

namespace arbor::sim {

struct NoiseModel {
  double sigma_translation = 0.05;  ///< metres, per axis
  double sigma_rotation = 0.01;     ///< radians, per axis
  /// Ω written = information_scale · Σ⁻¹, every edge; finite and > 0 (header comment).
  double information_scale = 1.0;
  /// Loop closures (|i − j| > 1) are drawn with both sigmas times this (their Ω written from
  /// their own Σ): > 1 for closures less precise than a step of odometry, as a scan match at a
  /// revisit is, so that a closure is not nearly all absorbed by its loop at the optimum.
  double closure_sigma_factor = 1.0;
  /// A heavy tail of the closures' noise: each loop closure is drawn, with this probability,
  /// with its sigmas times closure_tail_factor, its Ω written as for the others (a front end
  /// that cannot tell its worse matches). 0: none (no draw is spent on it).
  double closure_tail_fraction = 0.0;
  double closure_tail_factor = 1.0;  ///< ≥ 1
};

struct ManhattanOptions {
  int poses = 3500;
  int grid = 10;                     ///< the world is grid × grid cells of unit size
  double turn_probability = 0.3;     ///< chance of a ±90° turn at each step
  double closure_probability = 0.3;  ///< chance of closing a loop on a revisited cell
  int max_closures_per_pose = 1;
  NoiseModel noise{0.05, 0.01};
  std::uint64_t seed = 1;
};

struct SphereOptions {
  int rings = 20;
  int poses_per_ring = 50;
  double radius = 10.0;
  NoiseModel noise{0.05, 0.01};
  std::uint64_t seed = 1;
};

struct GridOptions {
  int poses = 1000;
  int size = 6;  ///< a size³ lattice of unit spacing
  double closure_probability = 0.5;
  int max_closures_per_pose = 2;
  NoiseModel noise{0.05, 0.01};
  std::uint64_t seed = 1;
};

/// A generated graph: `graph.poses` holds the noisy odometry initial estimate
/// (has_initial_estimate = true); `truth` holds the ground truth.
template <class Group>
struct Simulation {
  PoseGraph<Group> graph;
  std::vector<Group> truth;
};

Simulation<SE2> manhattanWorld(const ManhattanOptions& options);
Simulation<SE3> sphereWorld(const SphereOptions& options);
Simulation<SE3> gridWorld(const GridOptions& options);

/// Builds a graph from ground-truth poses and a list of (i, j) pairs: noisy measurements,
/// noisy odometry initial estimate (chain of the edges (k−1, k), which must be present).
/// Throws std::invalid_argument for a bad pair, a missing odometry edge, or sigmas or an
/// information_scale that are not finite and positive.
template <class Group>
Simulation<Group> simulate(const std::vector<Group>& truth,
                           const std::vector<std::pair<int, int>>& pairs, const NoiseModel& noise,
                           std::uint64_t seed);

}  // namespace arbor::sim
