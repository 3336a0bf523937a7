#include "arbor_slam/tools/cli/trajectory_errors.h"

#include <algorithm>
#include <cmath>
#include <numeric>
#include <stdexcept>
#include <string>

#include "arbor_slam/core/rigid_alignment.h"

namespace arbor::cli {

std::vector<std::pair<int, int>> associateByTime(const Trajectory& estimate,
                                                 const Trajectory& reference, double max_diff) {
  std::vector<int> order(reference.stamps.size());
  std::iota(order.begin(), order.end(), 0);
  std::sort(order.begin(), order.end(),
            [&](int a, int b) { return reference.stamps[a] < reference.stamps[b]; });
  std::vector<double> sorted(order.size());
  for (size_t k = 0; k < order.size(); ++k) sorted[k] = reference.stamps[order[k]];
  std::vector<std::pair<int, int>> pairs;
  for (int e = 0; e < static_cast<int>(estimate.stamps.size()); ++e) {
    const double s = estimate.stamps[e];
    const auto it = std::lower_bound(sorted.begin(), sorted.end(), s);
    int best = -1;
    double best_diff = max_diff;
    for (auto c : {it, it == sorted.begin() ? it : it - 1}) {
      if (c == sorted.end()) continue;
      const double diff = std::abs(*c - s);
      if (diff <= best_diff) {
        best_diff = diff;
        best = order[c - sorted.begin()];
      }
    }
    if (best >= 0) pairs.emplace_back(e, best);
  }
  return pairs;
}

TrajectoryErrors trajectoryErrors(const Trajectory& estimate, const Trajectory& reference,
                                  double max_diff) {
  const auto pairs = associateByTime(estimate, reference, max_diff);
  if (pairs.size() < 2)
    throw std::invalid_argument(std::to_string(pairs.size()) + " of the estimate's " +
                                std::to_string(estimate.poses.size()) +
                                " poses have a reference pose within " + std::to_string(max_diff) +
                                " in time: at least 2 are needed");
  TrajectoryErrors r;
  r.associated = static_cast<int>(pairs.size());
  std::vector<Eigen::Vector3d> p, q;
  for (const auto& [e, f] : pairs) {
    p.push_back(estimate.poses[e].translation());
    q.push_back(reference.poses[f].translation());
  }
  r.alignment = rigidAlignment<SE3>(p, q, std::vector<double>(p.size(), 1.0));
  double sum2 = 0, sum = 0;
  for (size_t k = 0; k < p.size(); ++k) {
    const double d = (r.alignment.act(p[k]) - q[k]).norm();
    sum2 += d * d;
    sum += d;
    r.ate_max = std::max(r.ate_max, d);
  }
  r.ate_rmse = std::sqrt(sum2 / double(p.size()));
  r.ate_mean = sum / double(p.size());
  double rpe2 = 0;
  for (size_t k = 0; k + 1 < pairs.size(); ++k) {
    const SE3 estimated =
        estimate.poses[pairs[k].first].between(estimate.poses[pairs[k + 1].first]);
    const SE3 expected =
        reference.poses[pairs[k].second].between(reference.poses[pairs[k + 1].second]);
    rpe2 += expected.between(estimated).translation().squaredNorm();
    ++r.rpe_pairs;
  }
  r.rpe_rmse = std::sqrt(rpe2 / double(r.rpe_pairs));
  return r;
}

}  // namespace arbor::cli
