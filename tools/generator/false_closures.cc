#include "arbor_slam/tools/generator/false_closures.h"

#include <algorithm>
#include <climits>
#include <cmath>
#include <set>
#include <sstream>
#include <stdexcept>
#include <string>

namespace arbor::sim {
namespace {

// One SplitMix64 step (Steele, Lea & Flood 2014): a seed S and S + 1 give unrelated streams.
std::uint64_t mixSeed(std::uint64_t z) {
  z += 0x9e3779b97f4a7c15ULL;
  z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ULL;
  z = (z ^ (z >> 27)) * 0x94d049bb133111ebULL;
  return z ^ (z >> 31);
}

using Pair = std::pair<int, int>;

std::string str(double v) {
  std::ostringstream os;
  os << v;
  return os.str();
}

Pair ordered(int a, int b) { return a < b ? Pair{a, b} : Pair{b, a}; }

// Pose pairs the false closures must avoid, ordered: those of the graph's own edges, then those
// drawn.
template <class Group>
std::set<Pair> existingPairs(const PoseGraph<Group>& graph) {
  std::set<Pair> taken;
  for (const auto& e : graph.edges) taken.insert(ordered(e.i, e.j));
  return taken;
}

// Free pairs with j − i in [lo, hi]: Σ_{d=lo}^{min(hi, n−1)} (n − d) minus those the graph's
// edges take.
std::int64_t freePairs(int n, int lo, int hi, const std::set<Pair>& taken) {
  std::int64_t count = 0;
  for (std::int64_t d = lo; d <= std::min(hi, n - 1); ++d) count += n - d;
  for (const auto& [i, j] : taken) {
    if (j - i >= lo && j - i <= hi) --count;
  }
  return count;
}

// The largest |translation component| over the real loop closures.
template <class Group>
double largestClosureTranslation(const PoseGraph<Group>& graph) {
  double largest = 0.0;
  for (const auto& e : graph.edges) {
    if (std::abs(e.i - e.j) > 1) {
      largest = std::max(largest, e.measurement.translation().cwiseAbs().maxCoeff());
    }
  }
  return largest;
}

}  // namespace

const char* toString(OutlierPolicy policy) {
  switch (policy) {
    case OutlierPolicy::kRandom:
      return "random";
    case OutlierPolicy::kLocal:
      return "local";
    case OutlierPolicy::kGroup:
      return "group";
  }
  return "?";
}

std::optional<OutlierPolicy> parseOutlierPolicy(const std::string& name) {
  for (OutlierPolicy p : {OutlierPolicy::kRandom, OutlierPolicy::kLocal, OutlierPolicy::kGroup}) {
    if (name == toString(p)) return p;
  }
  return std::nullopt;
}

template <class Group>
int countLoopClosures(const PoseGraph<Group>& graph) {
  return static_cast<int>(std::count_if(graph.edges.begin(), graph.edges.end(),
                                        [](const auto& e) { return std::abs(e.i - e.j) > 1; }));
}

int falseClosureCount(double fraction, int loop_closures) {
  if (!std::isfinite(fraction) || fraction < 0) {
    throw std::invalid_argument("outlier fraction must be finite and >= 0, not " + str(fraction));
  }
  // round half to even: ⌊x⌋, and one more above the half or at the half when ⌊x⌋ is odd.
  const double x = fraction * loop_closures;
  if (!(x < static_cast<double>(INT_MAX))) {
    throw std::invalid_argument("outlier fraction " + str(fraction) + " of " +
                                std::to_string(loop_closures) + " loop closures is too many");
  }
  const double low = std::floor(x);
  const double rest = x - low;
  const bool up = rest > 0.5 || (rest == 0.5 && std::fmod(low, 2.0) != 0.0);
  return static_cast<int>(low) + (up ? 1 : 0);
}

template <>
SE2 randomPose<SE2>(Random& rng, double h) {
  const double x = h * (2.0 * rng.uniform() - 1.0);
  const double y = h * (2.0 * rng.uniform() - 1.0);
  return SE2(x, y, M_PI * (2.0 * rng.uniform() - 1.0));
}

// Shoemake, "Uniform random rotations" (Graphics Gems III, 1992): with u₁, u₂, u₃ uniform in
// [0, 1), q = (√(1−u₁) sin 2πu₂, √(1−u₁) cos 2πu₂, √u₁ sin 2πu₃, √u₁ cos 2πu₃) is uniform on
// S³, hence R(q) uniform (Haar) on SO(3); q and −q are one rotation, we keep w ≥ 0.
template <>
SE3 randomPose<SE3>(Random& rng, double h) {
  Eigen::Vector3d t;
  for (int k = 0; k < 3; ++k) t(k) = h * (2.0 * rng.uniform() - 1.0);
  const double u1 = rng.uniform(), u2 = rng.uniform(), u3 = rng.uniform();
  const double a = std::sqrt(1.0 - u1), b = std::sqrt(u1);
  Eigen::Quaterniond q(b * std::cos(2.0 * M_PI * u3), a * std::sin(2.0 * M_PI * u2),
                       a * std::cos(2.0 * M_PI * u2), b * std::sin(2.0 * M_PI * u3));
  if (q.w() < 0) q.coeffs() = -q.coeffs();
  return SE3(q, t);
}

template <class Group>
FalseClosures<Group> addFalseClosures(const PoseGraph<Group>& graph, const OutlierOptions& o) {
  const int n = graph.numPoses();
  const int loop_closures = countLoopClosures(graph);
  const int count = falseClosureCount(o.fraction, loop_closures);
  if (n < 2) {
    throw std::invalid_argument("false loop closures need at least two poses, the graph has " +
                                std::to_string(n));
  }
  if (o.group_size < 1) {
    throw std::invalid_argument("outlier group size must be >= 1, not " +
                                std::to_string(o.group_size));
  }
  if (o.local_min < 2 || o.local_max < o.local_min) {
    throw std::invalid_argument("outlier local window must satisfy 2 <= min <= max, not [" +
                                std::to_string(o.local_min) + ", " + std::to_string(o.local_max) +
                                "]");
  }
  if (o.policy == OutlierPolicy::kLocal && n - 1 < o.local_min) {
    throw std::invalid_argument("local outliers pair poses " + std::to_string(o.local_min) + "-" +
                                std::to_string(o.local_max) + " apart, the graph has " +
                                std::to_string(n) + " poses (needs at least " +
                                std::to_string(o.local_min + 1) + ")");
  }
  const int group = std::min(o.group_size, std::max(count, 1));
  if (o.policy == OutlierPolicy::kGroup && n < group + 2) {
    throw std::invalid_argument(
        "a group of " + std::to_string(group) + " consecutive false closures needs at least " +
        std::to_string(group + 2) + " poses, the graph has " + std::to_string(n));
  }
  std::set<Pair> taken = existingPairs(graph);
  const bool local = o.policy == OutlierPolicy::kLocal;
  const std::int64_t free =
      freePairs(n, local ? o.local_min : 2, local ? o.local_max : INT_MAX - 1, taken);
  if (count > free) {
    throw std::invalid_argument(std::to_string(count) + " false loop closures (fraction " +
                                str(o.fraction) + " of " + std::to_string(loop_closures) +
                                ") but only " + std::to_string(free) +
                                " free pose pairs for policy " + toString(o.policy));
  }

  FalseClosures<Group> out;
  out.graph = graph;
  out.first_false = graph.numEdges();
  if (count == 0) return out;
  std::vector<int> closures;  // the real loop closures, whose Ω the false edges copy
  for (int k = 0; k < graph.numEdges(); ++k) {
    if (std::abs(graph.edges[k].i - graph.edges[k].j) > 1) closures.push_back(k);
  }
  const double h = 3.0 * std::max(1.0, largestClosureTranslation(graph));
  Random rng(mixSeed(o.seed));
  auto append = [&](int i, int j, const Group& z) {
    const auto& omega = graph.edges[closures[rng.index(static_cast<int>(closures.size()))]];
    out.graph.edges.push_back(RelativePoseEdge<Group>::make(i, j, z, omega.information));
    out.pairs.emplace_back(i, j);
    taken.insert({i, j});
  };
  // Rejection sampling: a draw that hits a taken pair (or, for a group, a run holding one) is
  // drawn again. With count ≤ free the expected draws are modest unless nearly every free pair
  // is asked for; the cap turns that case into an error instead of a long wait.
  const std::int64_t max_draws = 1000 + 1000 * static_cast<std::int64_t>(count);
  std::int64_t draws = 0;
  auto tooMany = [&] {
    if (++draws <= max_draws) return;
    throw std::runtime_error("could not place " + std::to_string(count) +
                             " false loop closures (policy " + toString(o.policy) + ") in " +
                             std::to_string(max_draws) + " draws: too few free pose pairs");
  };
  while (static_cast<int>(out.pairs.size()) < count) {
    tooMany();
    if (o.policy == OutlierPolicy::kRandom) {
      const Pair p = ordered(rng.index(n), rng.index(n));
      if (p.second - p.first < 2 || taken.count(p)) continue;
      append(p.first, p.second, randomPose<Group>(rng, h));
    } else if (o.policy == OutlierPolicy::kLocal) {
      const int d = o.local_min + rng.index(o.local_max - o.local_min + 1);
      if (d > n - 1) continue;
      const int i = rng.index(n - d);
      if (taken.count({i, i + d})) continue;
      append(i, i + d, randomPose<Group>(rng, h));
    } else {
      const int g = std::min(o.group_size, count - static_cast<int>(out.pairs.size()));
      const Pair p = ordered(rng.index(n - g + 1), rng.index(n - g + 1));  // starts that fit
      if (p.second - p.first < 2) continue;
      bool free_run = true;
      for (int k = 0; k < g && free_run; ++k) {
        free_run = !taken.count({p.first + k, p.second + k});
      }
      if (!free_run) continue;
      const Group z = randomPose<Group>(rng, h);
      for (int k = 0; k < g; ++k) append(p.first + k, p.second + k, z);
    }
  }
  return out;
}

template int countLoopClosures(const PoseGraph<SE2>&);
template int countLoopClosures(const PoseGraph<SE3>&);
template FalseClosures<SE2> addFalseClosures(const PoseGraph<SE2>&, const OutlierOptions&);
template FalseClosures<SE3> addFalseClosures(const PoseGraph<SE3>&, const OutlierOptions&);

}  // namespace arbor::sim
