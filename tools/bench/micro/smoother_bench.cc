// Microbenchmarks of the incremental smoother (iSAM2, Kaess et al. IJRR 2012) through its online
// layer: a generated Manhattan world fed edge by edge in order of max(i, j), one update() per
// edge, as `arbor replay` does. Reports per-update latency percentiles, the peak RSS, and the
// update cost at several graph sizes (prefixes of one trajectory).
#include <algorithm>
#include <chrono>
#include <cmath>
#include <numeric>
#include <vector>

#include <benchmark/benchmark.h>

#include "arbor_slam/bayestree/online_smoother.h"
#include "arbor_slam/tools/bench/micro/bench_graphs.h"
#include "arbor_slam/tools/cli/replay_order.h"

namespace arbor {
namespace {

using Clock = std::chrono::steady_clock;

double millisecondsSince(Clock::time_point start) {
  return std::chrono::duration<double, std::milli>(Clock::now() - start).count();
}

/// Nearest-rank percentile p (0–100) of `ms`, which it sorts.
double percentile(std::vector<double>* ms, double p) {
  if (ms->empty()) return 0.0;
  std::sort(ms->begin(), ms->end());
  const size_t rank = static_cast<size_t>(std::ceil(p / 100.0 * ms->size()));
  return (*ms)[std::min(ms->size() - 1, rank == 0 ? 0 : rank - 1)];
}

double mean(const std::vector<double>& v) {
  return v.empty() ? 0.0 : std::accumulate(v.begin(), v.end(), 0.0) / v.size();
}

/// Per-update latencies and what each update did.
struct UpdateLog {
  std::vector<double> ms;
  std::vector<double> ms_relinearizing;  ///< updates that relinearised some variable
  double cliques = 0, variables = 0, solved = 0, updated = 0;

  void add(double latency_ms, const UpdateStats& u) {
    ms.push_back(latency_ms);
    if (u.variables_relinearized > 0) ms_relinearizing.push_back(latency_ms);
    cliques += u.cliques_reeliminated;
    updated += u.cliques_updated;
    variables += u.variables_reeliminated;
    solved += u.cliques_solved;
  }
};

void addLatencyCounters(benchmark::State& state, UpdateLog log) {
  std::vector<double>& ms = log.ms;
  state.counters["updates"] = static_cast<double>(ms.size());
  const double n = ms.empty() ? 1.0 : static_cast<double>(ms.size());
  state.counters["cliques_per_update"] = log.cliques / n;       // re-eliminated
  state.counters["vars_per_update"] = log.variables / n;        // re-eliminated
  state.counters["solved_per_update"] = log.solved / n;         // back-substituted
  state.counters["rank_updated_per_update"] = log.updated / n;  // loop closures folded in
  state.counters["relin_updates"] = static_cast<double>(log.ms_relinearizing.size());
  state.counters["relin_mean_ms"] = mean(log.ms_relinearizing);
  state.counters["mean_ms"] = mean(ms);
  state.counters["p50_ms"] = percentile(&ms, 50);
  state.counters["p90_ms"] = percentile(&ms, 90);
  state.counters["p99_ms"] = percentile(&ms, 99);
  state.counters["max_ms"] = ms.empty() ? 0.0 : ms.back();
}

/// Adds edge `e` of `graph` to the smoother (ids as keys).
template <class G>
void feed(const PoseGraph<G>& graph, int e, OnlineSmoother<G>* smoother) {
  const auto& edge = graph.edges[e];
  smoother->addEdge(graph.ids[edge.i], graph.ids[edge.j], edge.measurement, edge.information);
}

// The whole 2000-pose Manhattan world, one update per edge; one replay per iteration.
void BM_ReplayManhattan(benchmark::State& state) {
  const auto s = micro::manhattanGraph(static_cast<int>(state.range(0)));
  const auto order = cli::replayGroups(s.graph, /*per_pose=*/false);
  UpdateLog log;
  double F = 0, rss_end = 0, heap_end = 0;
  const bool peak_reset = micro::resetPeakRss();
  const double rss_before = micro::procStatusMiB("VmRSS");
  for (auto _ : state) {
    OnlineSmoother<SE2> smoother;
    log = UpdateLog();
    for (const auto& group : order) {
      for (int e : group) feed(s.graph, e, &smoother);
      const auto start = Clock::now();
      const UpdateStats u = smoother.update();
      log.add(millisecondsSince(start), u);
    }
    F = smoother.smoother().objective();
    rss_end = micro::procStatusMiB("VmRSS");
    heap_end = micro::heapInUseMiB();
  }
  state.counters["poses"] = s.graph.numPoses();
  state.counters["edges"] = s.graph.numEdges();
  state.counters["F_incremental"] = F;
  // VmHWM is the process's peak; after a successful reset it is the peak of this benchmark.
  state.counters["peak_rss_MiB"] = micro::procStatusMiB("VmHWM");
  state.counters["peak_is_local"] = peak_reset;
  state.counters["rss_before_MiB"] = rss_before;
  state.counters["rss_end_MiB"] = rss_end;    // with the smoother still alive
  state.counters["heap_end_MiB"] = heap_end;  // allocated and not freed, smoother alive
  addLatencyCounters(state, log);
}

constexpr int kWindow = 100;        // updates timed at each size
constexpr int kSeriesPoses = 4200;  // the trajectory the sizes are prefixes of (N + kWindow fit)

// Two growing worlds: the Manhattan world revisits the same 10 × 10 cells, so it gets denser
// as it grows; the sphere (rings of 50 poses, each closed to the ring below) keeps its
// density, its separators staying about one ring wide.
struct ManhattanSeries {
  using Group = SE2;
  static sim::Simulation<SE2> make() { return micro::manhattanGraph(kSeriesPoses); }
};
struct SphereSeries {
  using Group = SE3;
  static sim::Simulation<SE3> make() {
    sim::SphereOptions o;
    o.poses_per_ring = 50;
    o.rings = kSeriesPoses / o.poses_per_ring;
    return sim::sphereWorld(o);
  }
};

// The update cost at a graph size N: the smoother is built (untimed) from the edges among the
// first N poses of one trajectory, then each iteration feeds the next edge and runs one update().
template <class Series>
void BM_UpdateAtSize(benchmark::State& state) {
  using G = typename Series::Group;
  const int size = static_cast<int>(state.range(0));
  const auto s = Series::make();
  const auto order = cli::replayGroups(s.graph, /*per_pose=*/false);
  auto last = [&](int e) { return std::max(s.graph.edges[e].i, s.graph.edges[e].j); };
  const auto setup_start = Clock::now();
  OnlineSmoother<G> smoother;
  size_t next = 0;
  for (; next < order.size() && last(order[next][0]) < size; ++next) {
    feed(s.graph, order[next][0], &smoother);
    smoother.update();
  }
  state.counters["setup_s"] = millisecondsSince(setup_start) / 1e3;
  const double heap_before = micro::heapInUseMiB();
  UpdateLog log;
  for (auto _ : state) {
    if (next >= order.size()) {
      state.SkipWithError("graph too small for this size and window");
      break;
    }
    const auto start = Clock::now();
    feed(s.graph, order[next++][0], &smoother);
    const UpdateStats u = smoother.update();
    log.add(millisecondsSince(start), u);
  }
  state.SetComplexityN(size);
  state.counters["poses"] = smoother.smoother().numPoses();
  state.counters["cliques"] = smoother.smoother().numCliques();
  // With the smoother alive: the resident set, the allocated heap, and its growth over the window.
  state.counters["rss_MiB"] = micro::procStatusMiB("VmRSS");
  state.counters["heap_MiB"] = micro::heapInUseMiB();
  state.counters["heap_window_growth_MiB"] = micro::heapInUseMiB() - heap_before;
  addLatencyCounters(state, log);
}

BENCHMARK(BM_ReplayManhattan)
    ->ArgName("poses")
    ->Arg(2000)
    ->Iterations(1)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();
}  // namespace

namespace micro {

void registerUpdateAtSize(const std::vector<int>& sizes) {
  auto series = [&](const char* name, void (*function)(benchmark::State&)) {
    benchmark::internal::Benchmark* b = benchmark::RegisterBenchmark(name, function);
    b->ArgName("poses")->Iterations(kWindow)->Unit(benchmark::kMillisecond)->UseRealTime();
    for (int n : sizes) b->Arg(n);
    if (sizes.size() > 1) b->Complexity();
  };
  series("BM_UpdateAtSize/manhattan", BM_UpdateAtSize<ManhattanSeries>);
  series("BM_UpdateAtSize/sphere", BM_UpdateAtSize<SphereSeries>);
}

}  // namespace micro
}  // namespace arbor
