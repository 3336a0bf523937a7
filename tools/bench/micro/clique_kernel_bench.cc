// Microbenchmarks of the clique kernels (bayestree/dense_kernels.h): re-eliminating a clique
// (partial Cholesky of its frontal matrix) against folding one 3D factor into it (a rank-6 update
// of the same factor), at clique shapes seen on the 3D sets (frontal F, separator S dimensions).
#include <random>
#include <vector>

#include <benchmark/benchmark.h>
#include <Eigen/Core>

#include "arbor_slam/bayestree/dense_kernels.h"

namespace arbor {
namespace {

constexpr int kRank = 6;  // an SE(3) factor's rows

// An SPD frontal matrix of order F + S + 1 (the last row and column: the right-hand side).
Eigen::MatrixXd frontalMatrix(int F, int S) {
  std::mt19937_64 rng(7);
  std::normal_distribution<double> normal(0, 1);
  const int M = F + S + 1;
  Eigen::MatrixXd R(M, M);
  for (int k = 0; k < R.size(); ++k) R.data()[k] = normal(rng);
  return R * R.transpose() + M * Eigen::MatrixXd::Identity(M, M);
}

void shapeCounters(benchmark::State& state, int F, int S) {
  state.counters["F"] = F;
  state.counters["S"] = S;
}

void BM_CliqueReelimination(benchmark::State& state) {
  const int F = static_cast<int>(state.range(0)), S = static_cast<int>(state.range(1));
  const Eigen::MatrixXd H = frontalMatrix(F, S);
  const int M = F + S + 1;
  const Eigen::VectorXd dg = H.diagonal().head(F);
  Eigen::MatrixXd A(M, M);
  for (auto _ : state) {
    A = H;
    benchmark::DoNotOptimize(bayestree::partialCholesky(A.data(), M, F, M, dg.data()));
  }
  shapeCounters(state, F, S);
}

void BM_CliqueRankUpdate(benchmark::State& state) {
  const int F = static_cast<int>(state.range(0)), S = static_cast<int>(state.range(1));
  const int N = F + S, M = N + 1;
  Eigen::MatrixXd A = frontalMatrix(F, S);
  const Eigen::VectorXd dg = A.diagonal().head(F);
  bayestree::partialCholesky(A.data(), M, F, M, dg.data());
  Eigen::MatrixXd L = A.block(0, 0, N, F);
  Eigen::VectorXd d = A.row(N).head(F).transpose();
  std::mt19937_64 rng(8);
  std::normal_distribution<double> normal(0, 1e-3);
  Eigen::MatrixXd W0(M, kRank);
  for (int k = 0; k < W0.size(); ++k) W0.data()[k] = normal(rng);
  Eigen::MatrixXd W(M, kRank);
  for (auto _ : state) {
    W = W0;  // the factor enters at the clique's first column (the whole clique is updated)
    bayestree::partialCholeskyUpdate(L.data(), N, N, F, d.data(), W.data(), M, kRank);
    benchmark::DoNotOptimize(W.data());
  }
  shapeCounters(state, F, S);
}

// (F, S): a leaf-like clique, mid-tree cliques, torus3D's largest (about 570 frontal), the top
// of a 200,000-pose Manhattan world under nested dissection (`arbor bench tree`: F up to 561, S
// up to 915).
void cliqueShapes(benchmark::internal::Benchmark* b) {
  for (const auto& [F, S] : std::vector<std::pair<int, int>>{
           {6, 36}, {36, 120}, {120, 240}, {240, 480}, {570, 6}, {600, 900}})
    b->Args({F, S});
}

BENCHMARK(BM_CliqueReelimination)->Apply(cliqueShapes)->Unit(benchmark::kMicrosecond);
BENCHMARK(BM_CliqueRankUpdate)->Apply(cliqueShapes)->Unit(benchmark::kMicrosecond);

}  // namespace
}  // namespace arbor
