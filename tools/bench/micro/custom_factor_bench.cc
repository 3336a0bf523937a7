// Microbenchmarks of factors of your own (core/custom_factor.h): one Factor<G>::linearize (the
// whitened, padded blocks the smoother and the batch solvers use) of the example factors
// (core/example_factors.h), autodiff against analytic, beside the built-in relative pose.
#include <memory>
#include <vector>

#include <benchmark/benchmark.h>

#include "arbor_slam/core/example_factors.h"
#include "arbor_slam/core/factor.h"

namespace arbor {
namespace {

constexpr double kMinTime = 0.1;

template <class G>
std::vector<G> twoPoses() {
  typename G::Tangent a = G::Tangent::Constant(0.3), b = G::Tangent::Constant(-0.2);
  a(0) = 1.0;
  b(1) = 2.0;
  return {G::Exp(a), G::Exp(b)};
}

template <class G>
void linearizeLoop(benchmark::State& state, const Factor<G>& f) {
  std::vector<G> x = twoPoses<G>();
  typename Factor<G>::Linearization out;
  for (auto _ : state) {
    benchmark::DoNotOptimize(x.data());
    f.linearize(x, &out);
    benchmark::DoNotOptimize(out.r);
    benchmark::ClobberMemory();
  }
}

template <class G>
void BM_BuiltinRelativePose(benchmark::State& state) {
  const auto x = twoPoses<G>();
  using Edge = RelativePoseEdge<G>;
  linearizeLoop<G>(state, Edge::make(0, 1, x[0].between(x[1]), Edge::Matrix::Identity()));
}

template <class G>
void BM_CustomRangeAutoDiff(benchmark::State& state) {
  const Eigen::Matrix<double, G::kDim, 1> a = Eigen::Matrix<double, G::kDim, 1>::Constant(5);
  linearizeLoop<G>(state, CustomFactor<G>::make(examples::RangeFactor<G>::Create({a, 3.0}),
                                                Eigen::MatrixXd::Identity(1, 1), 0));
}

template <class G>
void BM_CustomRelativePositionAutoDiff(benchmark::State& state) {
  const Eigen::Matrix<double, G::kDim, 1> p = Eigen::Matrix<double, G::kDim, 1>::Constant(1);
  linearizeLoop<G>(state, CustomFactor<G>::make(examples::RelativePositionAutoDiff<G>::Create({p}),
                                                Eigen::MatrixXd::Identity(G::kDim, G::kDim), 0, 1));
}

template <class G>
void BM_CustomRelativePositionAnalytic(benchmark::State& state) {
  const Eigen::Matrix<double, G::kDim, 1> p = Eigen::Matrix<double, G::kDim, 1>::Constant(1);
  linearizeLoop<G>(
      state, CustomFactor<G>::make(std::make_shared<const examples::RelativePositionFactor<G>>(p),
                                   Eigen::MatrixXd::Identity(G::kDim, G::kDim), 0, 1));
}

void BM_CustomPlanarMotionAutoDiff(benchmark::State& state) {
  linearizeLoop<SE3>(state, CustomFactor<SE3>::make(examples::PlanarMotionAutoDiff::Create({}),
                                                    Eigen::MatrixXd::Identity(3, 3), 0));
}

void BM_CustomPlanarMotionAnalytic(benchmark::State& state) {
  linearizeLoop<SE3>(state,
                     CustomFactor<SE3>::make(std::make_shared<const examples::PlanarMotionFactor>(),
                                             Eigen::MatrixXd::Identity(3, 3), 0));
}

BENCHMARK_TEMPLATE(BM_BuiltinRelativePose, SE2)->MinTime(kMinTime);
BENCHMARK_TEMPLATE(BM_BuiltinRelativePose, SE3)->MinTime(kMinTime);
BENCHMARK_TEMPLATE(BM_CustomRangeAutoDiff, SE2)->MinTime(kMinTime);
BENCHMARK_TEMPLATE(BM_CustomRangeAutoDiff, SE3)->MinTime(kMinTime);
BENCHMARK_TEMPLATE(BM_CustomRelativePositionAutoDiff, SE2)->MinTime(kMinTime);
BENCHMARK_TEMPLATE(BM_CustomRelativePositionAutoDiff, SE3)->MinTime(kMinTime);
BENCHMARK_TEMPLATE(BM_CustomRelativePositionAnalytic, SE2)->MinTime(kMinTime);
BENCHMARK_TEMPLATE(BM_CustomRelativePositionAnalytic, SE3)->MinTime(kMinTime);
BENCHMARK(BM_CustomPlanarMotionAutoDiff)->MinTime(kMinTime);
BENCHMARK(BM_CustomPlanarMotionAnalytic)->MinTime(kMinTime);

}  // namespace
}  // namespace arbor
