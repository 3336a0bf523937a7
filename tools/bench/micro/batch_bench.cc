// Microbenchmarks of whole-graph work on generated graphs: the objective F = Σ eᵀΩe, one batch
// Levenberg–Marquardt solve from a spanning-tree start, and the initialisations.
#include <benchmark/benchmark.h>

#include "arbor_slam/core/batch_solver.h"
#include "arbor_slam/core/initialization.h"
#include "arbor_slam/tools/bench/micro/bench_graphs.h"

namespace arbor {
namespace {

constexpr int kManhattanPoses = 2000;
constexpr int kGridPoses = 2000;

template <class G>
sim::Simulation<G> generated() {
  if constexpr (G::kDoF == 3) {
    return micro::manhattanGraph(kManhattanPoses);
  } else {
    return micro::gridGraph(kGridPoses);
  }
}

template <class G>
void describe(benchmark::State& state, const PoseGraph<G>& graph) {
  state.counters["poses"] = graph.numPoses();
  state.counters["edges"] = graph.numEdges();
}

template <class G>
void BM_Objective(benchmark::State& state) {
  const sim::Simulation<G> s = generated<G>();
  for (auto _ : state) benchmark::DoNotOptimize(objective(s.graph, s.graph.poses));
  describe(state, s.graph);
  state.SetItemsProcessed(state.iterations() * s.graph.numEdges());
}

template <class G>
void BM_BatchLM(benchmark::State& state) {
  const sim::Simulation<G> s = generated<G>();
  const std::vector<G> start = spanningTreeInitialization(s.graph);
  BatchSummary summary;
  for (auto _ : state) {
    state.PauseTiming();
    std::vector<G> poses = start;
    state.ResumeTiming();
    summary = solveBatch(s.graph, &poses);
    benchmark::DoNotOptimize(poses.data());
  }
  describe(state, s.graph);
  state.counters["iterations"] = summary.iterations;
  state.counters["F_initial"] = summary.F_initial;
  state.counters["F_final"] = summary.F_final;
  state.counters["converged"] = summary.termination == Termination::kConverged;
}

template <class G>
void BM_SpanningTreeInit(benchmark::State& state) {
  const sim::Simulation<G> s = generated<G>();
  double F = 0;
  for (auto _ : state) {
    const std::vector<G> poses = spanningTreeInitialization(s.graph);
    benchmark::DoNotOptimize(poses.data());
    state.PauseTiming();
    F = objective(s.graph, poses);
    state.ResumeTiming();
  }
  describe(state, s.graph);
  state.counters["F"] = F;
}

template <class G>
void BM_ChordalInit(benchmark::State& state) {
  const sim::Simulation<G> s = generated<G>();
  double F = 0;
  for (auto _ : state) {
    const std::vector<G> poses = chordalInitialization(s.graph);
    benchmark::DoNotOptimize(poses.data());
    state.PauseTiming();
    F = objective(s.graph, poses);
    state.ResumeTiming();
  }
  describe(state, s.graph);
  state.counters["F"] = F;
}

// SE2: the Manhattan world; SE3: the 3D grid world.
BENCHMARK_TEMPLATE(BM_Objective, SE2)
    ->Name("BM_Objective/manhattan2000")
    ->Unit(benchmark::kMicrosecond);
BENCHMARK_TEMPLATE(BM_Objective, SE3)->Name("BM_Objective/grid2000")->Unit(benchmark::kMicrosecond);
BENCHMARK_TEMPLATE(BM_SpanningTreeInit, SE2)
    ->Name("BM_SpanningTreeInit/manhattan2000")
    ->Unit(benchmark::kMillisecond);
BENCHMARK_TEMPLATE(BM_SpanningTreeInit, SE3)
    ->Name("BM_SpanningTreeInit/grid2000")
    ->Unit(benchmark::kMillisecond);
BENCHMARK_TEMPLATE(BM_ChordalInit, SE2)
    ->Name("BM_ChordalInit/manhattan2000")
    ->Unit(benchmark::kMillisecond);
BENCHMARK_TEMPLATE(BM_ChordalInit, SE3)
    ->Name("BM_ChordalInit/grid2000")
    ->Unit(benchmark::kMillisecond);
BENCHMARK_TEMPLATE(BM_BatchLM, SE2)
    ->Name("BM_BatchLM/manhattan2000")
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();
BENCHMARK_TEMPLATE(BM_BatchLM, SE3)
    ->Name("BM_BatchLM/grid2000")
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

}  // namespace
}  // namespace arbor
