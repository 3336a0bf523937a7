#include "arbor_slam/tools/generator/road_world.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "arbor_slam/tools/generator/random.h"

namespace arbor::sim {
namespace {

// A pose of the car in the plane.
struct PlanarPose {
  double x = 0, y = 0, heading = 0;
};

struct Route {
  std::vector<PlanarPose> poses;
  std::vector<std::pair<int, int>> pairs;  ///< odometry (k − 1, k) and the loop closures
};

double wrapAngle(double a) { return std::remainder(a, 2.0 * M_PI); }

// The intersection after `at`, arrived at from `from` (lattice coordinates).
std::pair<int, int> nextIntersection(Random& rng, const RoadOptions& o, std::pair<int, int> from,
                                     std::pair<int, int> at) {
  const int dx = at.first - from.first, dy = at.second - from.second;
  auto inside = [&](std::pair<int, int> p) {
    return p.first >= 0 && p.second >= 0 && p.first <= o.blocks && p.second <= o.blocks;
  };
  const std::pair<int, int> straight{at.first + dx, at.second + dy};
  const std::pair<int, int> left{at.first - dy, at.second + dx};
  const std::pair<int, int> right{at.first + dy, at.second - dx};
  if (inside(straight) && rng.uniform() < o.straight_probability) return straight;
  std::vector<std::pair<int, int>> turns;
  for (const auto& p : {left, right}) {
    if (inside(p)) turns.push_back(p);
  }
  if (turns.empty()) return inside(straight) ? straight : from;  // a dead end: back
  return turns[rng.index(static_cast<int>(turns.size()))];
}

// Earlier poses by the planar cell of side closure_radius they fall in.
class PlaceIndex {
 public:
  explicit PlaceIndex(double cell) : cell_(cell) {}
  void add(int k, const PlanarPose& p) { cells_[key(p.x, p.y)].push_back(k); }
  // The nearest pose j ≤ last within `radius` of p; −1 if none.
  int nearest(const std::vector<PlanarPose>& poses, const PlanarPose& p, double radius,
              int last) const {
    const auto [cx, cy] = key(p.x, p.y);
    int best = -1;
    double best_d2 = radius * radius;
    for (long ix = cx - 1; ix <= cx + 1; ++ix) {
      for (long iy = cy - 1; iy <= cy + 1; ++iy) {
        const auto it = cells_.find({ix, iy});
        if (it == cells_.end()) continue;
        for (const int j : it->second) {
          if (j > last) continue;
          const double ex = poses[j].x - p.x, ey = poses[j].y - p.y;
          const double d2 = ex * ex + ey * ey;
          if (d2 <= best_d2) {
            best_d2 = d2;
            best = j;
          }
        }
      }
    }
    return best;
  }

 private:
  std::pair<long, long> key(double x, double y) const {
    return {static_cast<long>(std::floor(x / cell_)), static_cast<long>(std::floor(y / cell_))};
  }
  double cell_;
  std::map<std::pair<long, long>, std::vector<int>> cells_;
};

Route drive(const RoadOptions& o) {
  checkRoadOptions(o);
  Random rng(o.seed);
  Route route;
  const double radius = o.step / o.max_turn;  // turning radius
  std::pair<int, int> from{0, 0}, at{1, 0};   // heading east from the corner
  PlanarPose car;
  PlaceIndex places(o.closure_radius);
  int last_closure = -o.closure_gap;
  for (int k = 0; k < o.poses; ++k) {
    if (k > 0) {
      const double tx = at.first * o.block_length, ty = at.second * o.block_length;
      const double turn = wrapAngle(std::atan2(ty - car.y, tx - car.x) - car.heading);
      car.heading = wrapAngle(car.heading + std::clamp(turn, -o.max_turn, o.max_turn));
      car.x += o.step * std::cos(car.heading);
      car.y += o.step * std::sin(car.heading);
      route.pairs.emplace_back(k - 1, k);
      if (std::hypot(tx - car.x, ty - car.y) < std::max(radius, o.step)) {
        const auto next = nextIntersection(rng, o, from, at);
        from = at;
        at = next;
      }
    }
    route.poses.push_back(car);
    if (k - last_closure >= o.closure_gap && k >= o.min_loop) {
      const int j = places.nearest(route.poses, car, o.closure_radius, k - o.min_loop);
      if (j >= 0 && rng.uniform() < o.closure_probability) {
        route.pairs.emplace_back(j, k);
        last_closure = k;
      }
    }
    places.add(k, car);
  }
  return route;
}

double groundHeight(const RoadOptions& o, double x, double y) {
  const double w = 2.0 * M_PI / o.hill_length;
  return o.hill_height * std::sin(w * x) * std::sin(w * y);
}

}  // namespace

RoadOptions vehicleOptions() { return RoadOptions{}; }  // the defaults: road_world.h

RoadOptions smallLoopOptions() {
  RoadOptions o;
  o.poses = 1000;
  o.blocks = 3;
  o.block_length = 12.0;
  o.step = 1.0;
  o.max_turn = 0.25;
  o.closure_radius = 0.5;
  o.min_loop = 30;
  o.closure_gap = 6;
  o.closure_probability = 0.6;
  o.hill_height = 1.0;
  o.hill_length = 80.0;
  return o;
}

void checkRoadOptions(const RoadOptions& o) {
  auto bad = [](const std::string& field, double value, const char* rule) {
    throw std::invalid_argument("road world: " + field + " must be " + rule + ", not " +
                                std::to_string(value));
  };
  if (o.poses < 2) bad("poses", o.poses, "at least 2");
  if (o.blocks < 1) bad("blocks", o.blocks, "at least 1");
  if (!(o.block_length > 0) || !std::isfinite(o.block_length))
    bad("block_length", o.block_length, "positive");
  if (!(o.step > 0) || !std::isfinite(o.step)) bad("step", o.step, "positive");
  if (!(o.max_turn > 0 && o.max_turn <= M_PI)) bad("max_turn", o.max_turn, "in (0, π]");
  if (!(o.straight_probability >= 0 && o.straight_probability <= 1))
    bad("straight_probability", o.straight_probability, "in [0, 1]");
  if (!(o.closure_radius > 0) || !std::isfinite(o.closure_radius))
    bad("closure_radius", o.closure_radius, "positive");
  if (o.min_loop < 2) bad("min_loop", o.min_loop, "at least 2");
  if (o.closure_gap < 1) bad("closure_gap", o.closure_gap, "at least 1");
  if (!(o.closure_probability >= 0 && o.closure_probability <= 1))
    bad("closure_probability", o.closure_probability, "in [0, 1]");
  if (!std::isfinite(o.hill_height)) bad("hill_height", o.hill_height, "finite");
  if (!(o.hill_length > 0) || !std::isfinite(o.hill_length))
    bad("hill_length", o.hill_length, "positive");
}

Simulation<SE2> roadWorld2(const RoadOptions& o) {
  const Route route = drive(o);
  std::vector<SE2> truth;
  truth.reserve(route.poses.size());
  for (const PlanarPose& p : route.poses) truth.emplace_back(p.x, p.y, p.heading);
  return simulate(truth, route.pairs, o.noise, o.seed + 1);
}

Simulation<SE3> roadWorld3(const RoadOptions& o) {
  const Route route = drive(o);
  std::vector<SE3> truth;
  truth.reserve(route.poses.size());
  const double h = 0.5 * o.step;  // the slope by central differences along the heading
  for (const PlanarPose& p : route.poses) {
    const double cx = std::cos(p.heading), cy = std::sin(p.heading);
    const double slope = (groundHeight(o, p.x + h * cx, p.y + h * cy) -
                          groundHeight(o, p.x - h * cx, p.y - h * cy)) /
                         (2.0 * h);
    // Body x forward, z up: yaw about z, then a pitch about y that lifts the nose uphill.
    const Eigen::Quaterniond q = Eigen::AngleAxisd(p.heading, Eigen::Vector3d::UnitZ()) *
                                 Eigen::AngleAxisd(-std::atan(slope), Eigen::Vector3d::UnitY());
    truth.emplace_back(q, Eigen::Vector3d(p.x, p.y, groundHeight(o, p.x, p.y)));
  }
  return simulate(truth, route.pairs, o.noise, o.seed + 1);
}

}  // namespace arbor::sim
