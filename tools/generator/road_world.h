// Car-like worlds, deterministic by seed: a vehicle drives a road lattice (a city of square
// blocks) and loop closures appear only where its route comes back to a place it has been.
//
//   route     the intersections of a (blocks + 1)² lattice, block_length apart; at each one the
//             car goes straight with straight_probability where it can, else turns left or
//             right (never back the way it came);
//   motion    one pose every `step` metres; the heading turns towards the next intersection by
//             at most max_turn a step (a turning radius of step / max_turn, so corners are arcs,
//             not right angles), and the car aims at the following intersection once within
//             that radius of the current one;
//   height    3D only: the ground is z = hill_height · sin(2πx / hill_length) · sin(2πy /
//             hill_length); the car's pitch follows the slope along its heading (roll 0), so
//             z and pitch change gently and a revisited place has the same height;
//   closures  pose k closes a loop to the nearest earlier pose j within closure_radius (in the
//             plane) with k − j ≥ min_loop, with closure_probability, and at least closure_gap
//             poses after the previous closure. The gap bounds the closures: at most
//             (poses − 1) / closure_gap + 1 of them.
//
//   noise     a car's odometry, 2 cm and 0.002 rad a step, and loop closures 10× less precise
//             (NoiseModel::closure_sigma_factor): with closures as precise as a step, a loop of
//             hundreds of steps absorbs nearly all of a closure's error, and the closures' χ²
//             at the clean optimum is about 1/40 of their noise's (vehicle, 2D, seed 1: median
//             0.0012 at information_scale 0.0236, 0.024 with the factor 10), far below what
//             real car graphs show. One closure in 20 is drawn 6× wider with the same Ω (a
//             heavy tail: a match a little off, that the front end cannot tell), so that a few
//             true closures score far above the median: at information_scale 0.02 their χ² at
//             the truth is 0.02 · 36 · χ²₃, mostly 0.3–10, inside χ²₃(0.99) = 11.3, as the true
//             closures the robust layer rejects on the car graphs of issue 52.
//
// Two presets: vehicleOptions() (3,000 poses, about 2% closures: long odometry chains, as a
// car's graph) and smallLoopOptions() (1,000 poses on a small lattice, about 100 closures).
// Measurements and Ω as simulate() makes them (graph_generator.h), NoiseModel's
// information_scale included.
#pragma once

#include <cstdint>

#include "arbor_slam/tools/generator/graph_generator.h"

namespace arbor::sim {

struct RoadOptions {
  int poses = 3000;
  int blocks = 6;                     ///< the lattice has (blocks + 1)² intersections, ≥ 1
  double block_length = 40.0;         ///< metres between neighbouring intersections
  double step = 2.0;                  ///< metres between consecutive poses
  double max_turn = 0.15;             ///< radians a step, at most
  double straight_probability = 0.5;  ///< at an intersection where going straight is possible
  double closure_radius = 1.0;        ///< metres, in the plane
  int min_loop = 100;                 ///< poses between the two ends of a closure, at least
  int closure_gap = 34;               ///< poses between two closures, at least (≥ 1)
  double closure_probability = 0.8;   ///< of a closure at a pose that may close one
  double hill_height = 4.0;           ///< 3D: metres, the terrain's amplitude
  double hill_length = 400.0;         ///< 3D: metres, the terrain's wavelength
  /// A car's odometry (2 cm and 0.002 rad a 2 m step); closures 10× less precise (20 cm,
  /// 0.02 rad), as a scan match at a revisit against a step of wheel and inertial odometry,
  /// one in 20 of them 6× worse again with the same Ω (header comment).
  NoiseModel noise{0.02, 0.002, 1.0, 10.0, 0.05, 6.0};
  std::uint64_t seed = 1;
};

/// The vehicle family's world: 3,000 poses over a 6 × 6-block city of 40 m blocks.
RoadOptions vehicleOptions();
/// The small-loop family's world: 1,000 poses of 1 m over a 3 × 3-block lattice of 12 m blocks.
RoadOptions smallLoopOptions();

/// Throws std::invalid_argument naming the first bad field.
void checkRoadOptions(const RoadOptions& options);

Simulation<SE2> roadWorld2(const RoadOptions& options);
Simulation<SE3> roadWorld3(const RoadOptions& options);

}  // namespace arbor::sim
