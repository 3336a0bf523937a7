// Microbenchmarks of the Lie-group operations and the relative-pose factor (core/).
#include <benchmark/benchmark.h>

#include "arbor_slam/core/relative_pose_factor.h"
#include "arbor_slam/core/se2.h"
#include "arbor_slam/core/se3.h"

namespace arbor {
namespace {

// Each of these takes nanoseconds: a tenth of a second per benchmark is plenty.
constexpr double kMinTime = 0.1;

SE2 pose2a() { return SE2(1.0, -2.0, 0.7); }
SE2 pose2b() { return SE2(1.3, -1.6, 1.1); }
SE3 pose3a() { return SE3::Exp((SE3::Tangent() << 0.3, -0.2, 1.0, 0.4, -0.1, 0.25).finished()); }
SE3 pose3b() { return SE3::Exp((SE3::Tangent() << 0.5, 0.1, 0.8, 0.35, 0.05, 0.3).finished()); }
SE2::Tangent tangent2() { return SE2::Tangent(0.05, -0.02, 0.03); }
SE3::Tangent tangent3() {
  return (SE3::Tangent() << 0.05, -0.02, 0.03, 0.01, -0.02, 0.015).finished();
}

template <class G>
G poseA() {
  if constexpr (G::kDoF == 3)
    return pose2a();
  else
    return pose3a();
}
template <class G>
G poseB() {
  if constexpr (G::kDoF == 3)
    return pose2b();
  else
    return pose3b();
}
template <class G>
typename G::Tangent tangentOf() {
  if constexpr (G::kDoF == 3)
    return tangent2();
  else
    return tangent3();
}

template <class G>
void BM_Compose(benchmark::State& state) {
  G a = poseA<G>(), b = poseB<G>();
  for (auto _ : state) {
    benchmark::DoNotOptimize(a);
    benchmark::DoNotOptimize(a.compose(b));
  }
}

template <class G>
void BM_ComposeJacobians(benchmark::State& state) {
  G a = poseA<G>(), b = poseB<G>();
  typename G::Jacobian Ja, Jb;
  for (auto _ : state) {
    benchmark::DoNotOptimize(a);
    benchmark::DoNotOptimize(a.compose(b, &Ja, &Jb));
    benchmark::ClobberMemory();
  }
}

template <class G>
void BM_Inverse(benchmark::State& state) {
  G a = poseA<G>();
  for (auto _ : state) {
    benchmark::DoNotOptimize(a);
    benchmark::DoNotOptimize(a.inverse());
  }
}

template <class G>
void BM_Exp(benchmark::State& state) {
  typename G::Tangent tau = tangentOf<G>();
  for (auto _ : state) {
    benchmark::DoNotOptimize(tau);
    benchmark::DoNotOptimize(G::Exp(tau));
  }
}

template <class G>
void BM_Log(benchmark::State& state) {
  G a = poseA<G>();
  for (auto _ : state) {
    benchmark::DoNotOptimize(a);
    benchmark::DoNotOptimize(a.Log());
  }
}

template <class G>
void BM_Retract(benchmark::State& state) {
  G a = poseA<G>();
  typename G::Tangent tau = tangentOf<G>();
  for (auto _ : state) {
    benchmark::DoNotOptimize(a);
    benchmark::DoNotOptimize(a.retract(tau));
  }
}

template <class G>
void BM_RelativePoseError(benchmark::State& state) {
  G z = poseA<G>().between(poseB<G>()), a = poseA<G>(), b = poseB<G>().retract(tangentOf<G>());
  for (auto _ : state) {
    benchmark::DoNotOptimize(a);
    benchmark::DoNotOptimize(relativePoseError(z, a, b));
  }
}

template <class G>
void BM_RelativePoseErrorJacobians(benchmark::State& state) {
  G z = poseA<G>().between(poseB<G>()), a = poseA<G>(), b = poseB<G>().retract(tangentOf<G>());
  typename G::Jacobian Ji, Jj;
  for (auto _ : state) {
    benchmark::DoNotOptimize(a);
    benchmark::DoNotOptimize(relativePoseError(z, a, b, &Ji, &Jj));
    benchmark::ClobberMemory();
  }
}

template <class G>
void BM_EdgeLinearize(benchmark::State& state) {
  using Edge = RelativePoseEdge<G>;
  typename Edge::Matrix omega = Edge::Matrix::Identity();
  omega.diagonal().head(G::kDim).setConstant(400.0);          // σ_t = 0.05
  omega.diagonal().tail(G::kDoF - G::kDim).setConstant(1e4);  // σ_r = 0.01
  const Edge edge = Edge::make(0, 1, poseA<G>().between(poseB<G>()), omega);
  G a = poseA<G>(), b = poseB<G>().retract(tangentOf<G>());
  typename Edge::Matrix Ai, Aj;
  typename Edge::Vector r;
  for (auto _ : state) {
    benchmark::DoNotOptimize(a);
    edge.linearize(a, b, &Ai, &Aj, &r);
    benchmark::DoNotOptimize(r);
    benchmark::ClobberMemory();
  }
}

BENCHMARK_TEMPLATE(BM_Compose, SE2)->MinTime(kMinTime);
BENCHMARK_TEMPLATE(BM_Compose, SE3)->MinTime(kMinTime);
BENCHMARK_TEMPLATE(BM_ComposeJacobians, SE2)->MinTime(kMinTime);
BENCHMARK_TEMPLATE(BM_ComposeJacobians, SE3)->MinTime(kMinTime);
BENCHMARK_TEMPLATE(BM_Inverse, SE2)->MinTime(kMinTime);
BENCHMARK_TEMPLATE(BM_Inverse, SE3)->MinTime(kMinTime);
BENCHMARK_TEMPLATE(BM_Exp, SE2)->MinTime(kMinTime);
BENCHMARK_TEMPLATE(BM_Exp, SE3)->MinTime(kMinTime);
BENCHMARK_TEMPLATE(BM_Log, SE2)->MinTime(kMinTime);
BENCHMARK_TEMPLATE(BM_Log, SE3)->MinTime(kMinTime);
BENCHMARK_TEMPLATE(BM_Retract, SE2)->MinTime(kMinTime);
BENCHMARK_TEMPLATE(BM_Retract, SE3)->MinTime(kMinTime);
BENCHMARK_TEMPLATE(BM_RelativePoseError, SE2)->MinTime(kMinTime);
BENCHMARK_TEMPLATE(BM_RelativePoseError, SE3)->MinTime(kMinTime);
BENCHMARK_TEMPLATE(BM_RelativePoseErrorJacobians, SE2)->MinTime(kMinTime);
BENCHMARK_TEMPLATE(BM_RelativePoseErrorJacobians, SE3)->MinTime(kMinTime);
BENCHMARK_TEMPLATE(BM_EdgeLinearize, SE2)->MinTime(kMinTime);
BENCHMARK_TEMPLATE(BM_EdgeLinearize, SE3)->MinTime(kMinTime);

}  // namespace
}  // namespace arbor
