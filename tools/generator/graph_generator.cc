#include "arbor_slam/tools/generator/graph_generator.h"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <map>
#include <stdexcept>
#include <string>

#include "arbor_slam/tools/generator/random.h"

namespace arbor::sim {
namespace {

template <class Group>
typename Group::Tangent drawNoise(Random& rng, const NoiseModel& noise) {
  typename Group::Tangent n;
  const int d = Group::kDim;
  for (int k = 0; k < Group::kDoF; ++k) {
    n(k) = (k < d ? noise.sigma_translation : noise.sigma_rotation) * rng.normal();
  }
  return n;
}

template <class Group>
Eigen::Matrix<double, Group::kDoF, Group::kDoF> information(const NoiseModel& noise) {
  Eigen::Matrix<double, Group::kDoF, Group::kDoF> omega;
  omega.setZero();
  for (int k = 0; k < Group::kDoF; ++k) {
    const double s = k < Group::kDim ? noise.sigma_translation : noise.sigma_rotation;
    omega(k, k) = noise.information_scale / (s * s);
  }
  return omega;
}

// Earlier visits to the cell just entered become loop closures (as in Olson's M3500).
void addClosures(Random& rng, const std::vector<int>& earlier, int k, double probability,
                 int max_closures, std::vector<std::pair<int, int>>* pairs) {
  std::vector<int> candidates;
  for (int e : earlier) {
    if (e < k - 1) candidates.push_back(e);
  }
  if (candidates.empty() || rng.uniform() >= probability) return;
  const int count = std::min<int>(max_closures, static_cast<int>(candidates.size()));
  for (int c = 0; c < count; ++c) {
    const int pick = c + rng.index(static_cast<int>(candidates.size()) - c);
    std::swap(candidates[c], candidates[pick]);
    pairs->emplace_back(candidates[c], k);
  }
}

}  // namespace

template <class Group>
Simulation<Group> simulate(const std::vector<Group>& truth,
                           const std::vector<std::pair<int, int>>& pairs, const NoiseModel& noise,
                           std::uint64_t seed) {
  for (const double v : {noise.sigma_translation, noise.sigma_rotation, noise.information_scale,
                         noise.closure_sigma_factor}) {
    if (!(v > 0) || !std::isfinite(v)) {
      throw std::invalid_argument(
          "simulate: noise sigmas, information_scale and closure_sigma_factor must be finite "
          "and positive, not " +
          std::to_string(v));
    }
  }
  if (!(noise.closure_tail_fraction >= 0 && noise.closure_tail_fraction <= 1) ||
      !(noise.closure_tail_factor >= 1) || !std::isfinite(noise.closure_tail_factor)) {
    throw std::invalid_argument(
        "simulate: closure_tail_fraction must be in [0, 1] and closure_tail_factor finite and "
        ">= 1, not " +
        std::to_string(noise.closure_tail_fraction) + " and " +
        std::to_string(noise.closure_tail_factor));
  }
  NoiseModel closure_noise = noise;  // the loop closures' (|i − j| > 1)
  closure_noise.sigma_translation *= noise.closure_sigma_factor;
  closure_noise.sigma_rotation *= noise.closure_sigma_factor;
  NoiseModel tail_noise = closure_noise;  // a closure of the tail: drawn wider, Ω as the others
  tail_noise.sigma_translation *= noise.closure_tail_factor;
  tail_noise.sigma_rotation *= noise.closure_tail_factor;
  Random rng(seed);
  Simulation<Group> sim;
  sim.truth = truth;
  const int n = static_cast<int>(truth.size());
  auto& g = sim.graph;
  for (int k = 0; k < n; ++k) {
    g.ids.push_back(k);
    g.index[k] = k;
  }
  const auto omega = information<Group>(noise);
  const auto closure_omega = information<Group>(closure_noise);
  std::vector<const Group*> odometry(n, nullptr);
  for (const auto& [i, j] : pairs) {
    if (i < 0 || j < 0 || i >= n || j >= n || i == j) {
      throw std::invalid_argument("simulate: bad edge pair");
    }
    const bool closure = std::abs(i - j) > 1;
    const bool tail =
        closure && noise.closure_tail_fraction > 0 && rng.uniform() < noise.closure_tail_fraction;
    const Group z = truth[i].between(truth[j]).compose(
        Group::Exp(drawNoise<Group>(rng, tail      ? tail_noise
                                         : closure ? closure_noise
                                                   : noise)));
    g.edges.push_back(RelativePoseEdge<Group>::make(i, j, z, closure ? closure_omega : omega));
  }
  for (const auto& e : g.edges) {
    if (e.j == e.i + 1 && !odometry[e.j]) odometry[e.j] = &e.measurement;
  }
  g.poses.resize(n);
  g.poses[0] = truth[0];
  for (int k = 1; k < n; ++k) {
    if (!odometry[k]) throw std::invalid_argument("simulate: missing odometry edge");
    g.poses[k] = g.poses[k - 1].compose(*odometry[k]);
  }
  g.has_initial_estimate = true;
  return sim;
}

Simulation<SE2> manhattanWorld(const ManhattanOptions& o) {
  Random rng(o.seed);
  std::vector<SE2> truth;
  std::vector<std::pair<int, int>> pairs;
  std::map<std::pair<int, int>, std::vector<int>> visits;
  int x = 0, y = 0, heading = 0;  // heading in quarter turns
  static const int dx[4] = {1, 0, -1, 0};
  static const int dy[4] = {0, 1, 0, -1};
  truth.emplace_back(0.0, 0.0, 0.0);
  visits[{0, 0}].push_back(0);
  for (int k = 1; k < o.poses; ++k) {
    if (rng.uniform() < o.turn_probability) heading = (heading + (rng.uniform() < 0.5 ? 1 : 3)) % 4;
    // Stay inside the grid: turn left until the next cell is inside.
    for (int tries = 0; tries < 4; ++tries) {
      const int nx = x + dx[heading], ny = y + dy[heading];
      if (nx >= 0 && ny >= 0 && nx < o.grid && ny < o.grid) break;
      heading = (heading + 1) % 4;
    }
    x += dx[heading];
    y += dy[heading];
    truth.emplace_back(x, y, heading * M_PI / 2.0);
    pairs.emplace_back(k - 1, k);
    auto& here = visits[{x, y}];
    addClosures(rng, here, k, o.closure_probability, o.max_closures_per_pose, &pairs);
    here.push_back(k);
  }
  return simulate(truth, pairs, o.noise, o.seed + 1);
}

Simulation<SE3> sphereWorld(const SphereOptions& o) {
  std::vector<SE3> truth;
  std::vector<std::pair<int, int>> pairs;
  for (int r = 0; r < o.rings; ++r) {
    const double polar = M_PI * (r + 1) / (o.rings + 1);
    for (int p = 0; p < o.poses_per_ring; ++p) {
      const double azimuth = 2.0 * M_PI * p / o.poses_per_ring;
      const Eigen::Quaterniond q = Eigen::AngleAxisd(azimuth, Eigen::Vector3d::UnitZ()) *
                                   Eigen::AngleAxisd(polar, Eigen::Vector3d::UnitY());
      const Eigen::Vector3d t =
          o.radius * Eigen::Vector3d(std::sin(polar) * std::cos(azimuth),
                                     std::sin(polar) * std::sin(azimuth), std::cos(polar));
      const int k = static_cast<int>(truth.size());
      truth.emplace_back(q, t);
      if (k > 0) pairs.emplace_back(k - 1, k);
      if (r > 0) pairs.emplace_back(k - o.poses_per_ring, k);
    }
  }
  return simulate(truth, pairs, o.noise, o.seed);
}

Simulation<SE3> gridWorld(const GridOptions& o) {
  Random rng(o.seed);
  std::vector<SE3> truth;
  std::vector<std::pair<int, int>> pairs;
  std::map<std::tuple<int, int, int>, std::vector<int>> visits;
  // Six axis directions; the pose's x axis points along the direction of travel.
  static const int dir[6][3] = {{1, 0, 0},  {-1, 0, 0}, {0, 1, 0},
                                {0, -1, 0}, {0, 0, 1},  {0, 0, -1}};
  auto orientation = [](int d) {
    const Eigen::Vector3d to(dir[d][0], dir[d][1], dir[d][2]);
    return Eigen::Quaterniond::FromTwoVectors(Eigen::Vector3d::UnitX(), to);
  };
  int p[3] = {0, 0, 0};
  int heading = 0;
  truth.emplace_back(orientation(0), Eigen::Vector3d::Zero());
  visits[{0, 0, 0}].push_back(0);
  for (int k = 1; k < o.poses; ++k) {
    if (rng.uniform() < 0.3) heading = rng.index(6);
    for (int tries = 0; tries < 6; ++tries) {
      bool inside = true;
      for (int a = 0; a < 3; ++a) {
        const int c = p[a] + dir[heading][a];
        inside = inside && c >= 0 && c < o.size;
      }
      if (inside) break;
      heading = (heading + 1) % 6;
    }
    for (int a = 0; a < 3; ++a) p[a] += dir[heading][a];
    truth.emplace_back(orientation(heading), Eigen::Vector3d(p[0], p[1], p[2]));
    pairs.emplace_back(k - 1, k);
    auto& here = visits[{p[0], p[1], p[2]}];
    addClosures(rng, here, k, o.closure_probability, o.max_closures_per_pose, &pairs);
    here.push_back(k);
  }
  return simulate(truth, pairs, o.noise, o.seed + 1);
}

template Simulation<SE2> simulate(const std::vector<SE2>&, const std::vector<std::pair<int, int>>&,
                                  const NoiseModel&, std::uint64_t);
template Simulation<SE3> simulate(const std::vector<SE3>&, const std::vector<std::pair<int, int>>&,
                                  const NoiseModel&, std::uint64_t);

}  // namespace arbor::sim
