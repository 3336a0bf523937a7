#include "arbor_slam/tools/bench/growth.h"

#include <algorithm>
#include <stdexcept>

#include "arbor_slam/core/latency_summary.h"
#include "arbor_slam/core/normal_equations.h"
#include "arbor_slam/tools/bench/format.h"
#include "arbor_slam/tools/cli/cli_common.h"
#include "arbor_slam/tools/cli/replay_order.h"

namespace arbor::bench {
namespace {

// The graph of the poses 0..m−1 and the edges among them, the first pose fixed.
template <class G>
PoseGraph<G> prefix(const PoseGraph<G>& graph, int m) {
  PoseGraph<G> p;
  p.ids.assign(graph.ids.begin(), graph.ids.begin() + m);
  for (int k = 0; k < m; ++k) p.index[p.ids[k]] = k;
  p.poses.assign(graph.poses.begin(), graph.poses.begin() + m);
  for (const auto& e : graph.edges)
    if (e.i < m && e.j < m) p.edges.push_back(e);
  p.fixed = {0};
  return p;
}

// The factorisation's flops and times for `graph` (at its initial poses), and the
// linearisation's with the faster back-end, each time the fastest of three runs.
template <class G>
void measureFactorization(const PoseGraph<G>& graph, GrowthSlice* slice) {
  double block_linearize_ms = 0, cholmod_linearize_ms = 0;
  for (CholeskyBackend backend : {CholeskyBackend::kBlock, CholeskyBackend::kCholmod}) {
    const bool block = backend == CholeskyBackend::kBlock;
    NormalEquations<G> equations(graph, backend);
    slice->factorization_flops = equations.factorizationFlops();
    double best = 0, best_linearize = 0;
    for (int run = 0; run < 3; ++run) {
      cli::Stopwatch linearize_clock;
      equations.linearize(graph.poses);
      const double l = 1e3 * linearize_clock.seconds();
      best_linearize = run == 0 ? l : std::min(best_linearize, l);
      cli::Stopwatch clock;
      if (!equations.factorize()) return;
      const double ms = 1e3 * clock.seconds();
      best = run == 0 ? ms : std::min(best, ms);
    }
    (block ? slice->block_ms : slice->cholmod_ms) = best;
    (block ? block_linearize_ms : cholmod_linearize_ms) = best_linearize;
  }
  slice->factorization_ms = std::min(slice->block_ms, slice->cholmod_ms);
  slice->linearization_ms =
      slice->block_ms <= slice->cholmod_ms ? block_linearize_ms : cholmod_linearize_ms;
}

}  // namespace

template <class G>
std::vector<GrowthSlice> growthSlices(const PoseGraph<G>& graph, const cli::ReplayResult<G>& replay,
                                      bool per_pose, int slices) {
  if (slices < 1) throw std::invalid_argument("growthSlices: slices must be at least 1");
  const auto groups = cli::replayGroups(graph, per_pose);
  if (groups.size() != replay.rows.size())
    throw std::invalid_argument("growthSlices: " + std::to_string(replay.rows.size()) +
                                " update rows for " + std::to_string(groups.size()) + " updates");
  const int n = graph.numPoses();
  std::vector<GrowthSlice> out;
  size_t u = 0;
  int known = 0;
  for (int s = 1; s <= slices; ++s) {
    GrowthSlice slice;
    const int limit = static_cast<int>(static_cast<long long>(n) * s / slices);
    std::vector<double> relin_ms, other_ms;
    double share = 0;
    for (; u < groups.size(); ++u) {
      const auto& last = graph.edges[groups[u].back()];
      const int after = std::max(known, std::max(last.i, last.j) + 1);
      if (after > limit) break;
      known = after;
      const cli::UpdateRow& row = replay.rows[u];
      if (row.latency_ms > slice.max_ms || slice.largest_kind.empty()) {
        slice.max_ms = row.latency_ms;
        slice.largest_step = row.step;
        slice.largest_kind = updateKind(row);
      }
      if (row.variables_relinearized > 0) {
        relin_ms.push_back(row.latency_ms);
        share += static_cast<double>(row.variables_relinearized) / known;
      } else {
        other_ms.push_back(row.latency_ms);
      }
      slice.edges = row.edges_so_far;
      slice.batch_updates += row.batch_reeliminations;
      slice.peak_rss_mb = static_cast<double>(row.peak_rss_kb) / 1024;
    }
    if (relin_ms.empty() && other_ms.empty()) continue;
    slice.poses = known;
    slice.rss_per_pose_kb = known > 0 ? 1024 * slice.peak_rss_mb / known : 0;
    slice.relin_updates = static_cast<int>(relin_ms.size());
    if (!relin_ms.empty()) {
      const LatencySummary l = summarizeLatency(relin_ms);
      slice.relin_p50_ms = l.p50;
      slice.relin_max_ms = l.max;
      slice.relin_share = share / static_cast<double>(relin_ms.size());
    }
    slice.other_updates = static_cast<int>(other_ms.size());
    if (!other_ms.empty()) {
      const LatencySummary l = summarizeLatency(other_ms);
      slice.other_p50_ms = l.p50;
      slice.other_p99_ms = l.p99;
    }
    if (known > 1) measureFactorization(prefix(graph, known), &slice);
    out.push_back(slice);
  }
  return out;
}

std::string updateKind(const cli::UpdateRow& row) {
  if (row.async_swapped > 0) return "swap";
  if (row.batch_reeliminations > 0) return "batch";
  if (row.variables_relinearized > 0) return "relinearisation";
  if (row.cliques_reeliminated > 2) return "top";
  if (row.cliques_updated > 0) return "fold-in";
  return "other";
}

void printGrowthTable(std::ostream& out, const std::vector<GrowthSlice>& slices) {
  // A ratio against issue 17's bound, marked where the bound applies (a factorisation of at
  // least 1 ms; timed) and is missed.
  auto bound = [](double ratio, double limit, double factorization_ms) {
    return fmt("%.2f", ratio) + (factorization_ms >= 1 && ratio > limit ? " (over)" : "");
  };
  out << "| poses | edges | factorisation MFlop | factorisation ms, block / CHOLMOD | relin. "
         "updates | relin. p50 "
         "ms | relin. max ms | relinearised | relin. / factorisation | other updates | other p50 "
         "ms | other p99 ms | largest ms | largest / factorisation | other p99 / factorisation "
         "| linearisation ms | (linearisation + factorisation) / factorisation | batch updates | "
         "peak RSS MB | RSS / pose KB | largest: update, kind |\n"
      << "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n";
  for (const GrowthSlice& s : slices) {
    const bool timed = s.factorization_ms > 0;
    out << "| " << s.poses << " | " << s.edges << " | " << fmt("%.1f", s.factorization_flops / 1e6)
        << " | " << (timed ? fmt("%.3f", s.block_ms) + " / " + fmt("%.3f", s.cholmod_ms) : "—")
        << " | " << s.relin_updates << " | " << fmt("%.3f", s.relin_p50_ms) << " | "
        << fmt("%.3f", s.relin_max_ms) << " | " << fmt("%.0f%%", 100 * s.relin_share) << " | "
        << (timed && s.relin_updates > 0 ? fmt("%.1f", s.relin_p50_ms / s.factorization_ms) : "—")
        << " | " << s.other_updates << " | " << fmt("%.3f", s.other_p50_ms) << " | "
        << fmt("%.3f", s.other_p99_ms) << " | " << fmt("%.3f", s.max_ms) << " | "
        << (timed ? bound(s.max_ms / s.factorization_ms, 1.5, s.factorization_ms) : "—") << " | "
        << (timed ? bound(s.other_p99_ms / s.factorization_ms, 0.25, s.factorization_ms) : "—")
        << " | " << (timed ? fmt("%.3f", s.linearization_ms) : "—") << " | "
        << (timed ? fmt("%.2f", (s.linearization_ms + s.factorization_ms) / s.factorization_ms)
                  : "—")
        << " | " << s.batch_updates << " | " << fmt("%.0f", s.peak_rss_mb) << " | "
        << fmt("%.2f", s.rss_per_pose_kb) << " | " << s.largest_step << ", " << s.largest_kind
        << " |\n";
  }
}

template std::vector<GrowthSlice> growthSlices(const PoseGraph<SE2>&, const cli::ReplayResult<SE2>&,
                                               bool, int);
template std::vector<GrowthSlice> growthSlices(const PoseGraph<SE3>&, const cli::ReplayResult<SE3>&,
                                               bool, int);

}  // namespace arbor::bench
