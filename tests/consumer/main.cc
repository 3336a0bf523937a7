// An external program on an installed Arbor: reads a g2o or TORO file, feeds its edges to the
// online smoother one update per edge in `arbor replay`'s order (by max(i, j) of the pose
// indices, then file order; tools/cli/replay_order.h), runs the final relinearise-all pass and
// prints F, the objective at the final estimate, as `arbor replay` reports it ("F final"; its
// --json "F_final"). It also prints how many threads OpenBLAS runs per call, which the library
// sets to 1 by itself (arbor/core/blas_threads.h), or "none" when the BLAS is not OpenBLAS.
//
//   arbor_consumer FILE [EXPECTED_F]
// With EXPECTED_F it exits 1 unless |F - EXPECTED_F| <= 1e-9 |EXPECTED_F|. Priors in the file
// are not fed (`arbor replay` feeds them; this program is for graphs of edges only).
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

#include <arbor/bayestree/online_smoother.h>
#include <arbor/core/pose_graph.h>
#include <arbor/io/pose_graph_file.h>

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
