// An external program on an installed Arbor: reads a g2o or TORO file, feeds its edges to the
// online smoother one update per edge in `arbor replay`'s order (by max(i, j) of the pose
// indices, then file order; tools/cli/replay_order.h), runs the final relinearise-all pass and
// prints F, the objective at the final estimate, as `arbor replay` reports it ("F final"; its
// --json "F_final"). It also prints how many threads OpenBLAS runs per call, which the library
// sets to 1 by itself (arbor_slam/core/blas_threads.h), or "none" when the BLAS is not OpenBLAS.
//
//   arbor_consumer FILE [EXPECTED_F]
// With EXPECTED_F it exits 1 unless |F - EXPECTED_F| <= 1e-9 |EXPECTED_F|. Priors in the file
// are not fed (`arbor replay` feeds them; this program is for graphs of edges only).
//
// It also uses a factor of its own (docs/design.md, "Factors of your own"): ranges to three
// beacons on a small square trajectory, an autodiff functor defined here, solved by the
// incremental smoother and by batch Gauss–Newton; it exits 1 unless both reach the truth the
// noise-free measurements describe (prints "custom_factor ok").
#include <dlfcn.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <exception>
#include <iomanip>
#include <iostream>
#include <numeric>
#include <string>
#include <variant>
#include <vector>

#include <arbor_slam/bayestree/incremental_smoother.h>
#include <arbor_slam/bayestree/online_smoother.h>
#include <arbor_slam/core/autodiff_factor.h>
#include <arbor_slam/core/batch_solver.h>
#include <arbor_slam/core/custom_factor.h>
#include <arbor_slam/core/factor.h>
#include <arbor_slam/core/pose_graph.h>
#include <arbor_slam/io/pose_graph_file.h>

namespace {

template <class G>
double replay(const arbor::PoseGraph<G>& graph) {
  std::vector<int> order(graph.edges.size());
  std::iota(order.begin(), order.end(), 0);
  auto last = [&](int e) { return std::max(graph.edges[e].i, graph.edges[e].j); };
  std::stable_sort(order.begin(), order.end(), [&](int a, int b) { return last(a) < last(b); });

  arbor::OnlineSmoother<G> smoother;
  for (int e : order) {
    const auto& edge = graph.edges[e];
    const arbor::EdgeResult r =
        smoother.addEdge(graph.ids[edge.i], graph.ids[edge.j], edge.measurement, edge.information);
    if (r.status == arbor::EdgeStatus::kRejected)
      std::cerr << "edge " << graph.ids[edge.i] << " -> " << graph.ids[edge.j]
                << " rejected: " << r.reason << "\n";
    smoother.update();
  }
  smoother.finalize();

  std::vector<G> poses = graph.poses;  // poses never reached keep their file value
  for (const auto& [id, pose] : smoother.estimates()) poses[graph.index.at(id)] = pose;
  return arbor::objective(graph, poses);
}

// e = ‖t(x) − b‖ − ρ: the range from a beacon b at a known position.
struct BeaconRange {
  Eigen::Vector2d beacon;
  double range;

  template <class T>
  Eigen::Matrix<T, 1, 1> operator()(const arbor::RigidMotion2<T>& x) const {
    return Eigen::Matrix<T, 1, 1>((x.t - beacon.cast<T>()).norm() - T(range));
  }
};

// Eight poses on a square, odometry edges and three ranges per pose; the first pose starts at
// the truth and the others off it. Returns the largest position error of either solution.
double customFactorError() {
  using arbor::SE2;
  std::vector<SE2> truth;
  for (int k = 0; k < 8; ++k) truth.emplace_back(k < 4 ? k : 3, k < 4 ? 0 : k - 3, 0.0);
  const std::vector<Eigen::Vector2d> beacons{{-2, 5}, {6, -1}, {6, 7}};
  arbor::SmootherOptions options;
  options.finalize_relative_tolerance = 1e-12;
  arbor::IncrementalSmoother<SE2> smoother(options);
  arbor::PoseGraph<SE2> graph;
  for (int k = 0; k < 8; ++k) {
    const SE2 start = truth[k].compose(SE2(0.2 * (k % 3), -0.1 * (k % 2), 0.05 * k));
    smoother.addPose(k == 0 ? truth[0] : start);
    graph.ids.push_back(k);
    graph.index[k] = k;
    graph.poses.push_back(k == 0 ? truth[0] : start);
    std::vector<arbor::Factor<SE2>> factors;
    if (k > 0)
      factors.emplace_back(arbor::RelativePoseEdge<SE2>::make(
          k - 1, k, truth[k - 1].between(truth[k]), 10 * Eigen::Matrix3d::Identity()));
    for (const auto& b : beacons) {
      const double range = (truth[k].translation() - b).norm();
      auto model = arbor::AutoDiffFactor<SE2, BeaconRange, 1>::Create({b, range}, "beacon_range");
      factors.emplace_back(
          arbor::CustomFactor<SE2>::make(model, Eigen::MatrixXd::Constant(1, 1, 100.0), k));
    }
    for (const auto& f : factors) {
      smoother.addFactor(f);
      arbor::addToGraph(f, &graph);
    }
    smoother.update();
  }
  smoother.relinearizeAll();
  std::vector<SE2> batch = graph.poses;
  arbor::solveBatch(graph, &batch,
                    arbor::batchOptions(arbor::BatchMethod::kGaussNewton, 50, 1e-14));
  double worst = 0;
  for (int k = 0; k < 8; ++k)
    worst = std::max({worst, (smoother.estimate(k).translation() - truth[k].translation()).norm(),
                      (batch[k].translation() - truth[k].translation()).norm()});
  return worst;
}

std::string blasThreads() {
  using GetThreads = int (*)();
  auto get = reinterpret_cast<GetThreads>(dlsym(RTLD_DEFAULT, "openblas_get_num_threads"));
  return get ? std::to_string(get()) : "none";
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 2 || argc > 3) {
    std::cerr << "usage: arbor_consumer FILE [EXPECTED_F]\n";
    return 2;
  }
  try {
    const arbor::AnyPoseGraph graph = arbor::readPoseGraphFile(argv[1]);
    const double F = std::visit([](const auto& g) { return replay(g); }, graph);
    std::cout << std::setprecision(17) << "F " << F << "\n"
              << "blas_threads " << blasThreads() << "\n";
    const double custom_error = customFactorError();
    if (!(custom_error < 1e-6)) {
      std::cerr << "custom factor: position error " << custom_error << " after the solves\n";
      return 1;
    }
    std::cout << "custom_factor ok\n";
    if (argc == 3) {
      const double expected = std::strtod(argv[2], nullptr);
      if (!(std::abs(F - expected) <= 1e-9 * std::abs(expected))) {
        std::cerr << "F " << F << " differs from the expected " << argv[2] << "\n";
        return 1;
      }
    }
  } catch (const std::exception& e) {
    std::cerr << e.what() << "\n";
    return 1;
  }
  return 0;
}
