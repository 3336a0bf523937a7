#include "arbor_slam/tools/cli/covariance_output.h"

#include <algorithm>
#include <charconv>
#include <fstream>
#include <numeric>
#include <ostream>
#include <stdexcept>

#include "arbor_slam/bayestree/incremental_smoother.h"
#include "arbor_slam/core/factor.h"

namespace arbor::cli {
namespace {

template <class Write>
void writeFile(const std::string& path, const Write& write) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  if (!out) throw std::runtime_error("cannot write " + path);
  write(out);
  out.close();
  if (!out) throw std::runtime_error("cannot write " + path);
}

}  // namespace

template <int D>
void writeCovariances(std::ostream& out, const std::vector<Key>& ids,
                      const std::vector<Eigen::Matrix<double, D, D>>& covariances) {
  if (ids.size() != covariances.size())
    throw std::invalid_argument("writeCovariances: " + std::to_string(ids.size()) + " ids for " +
                                std::to_string(covariances.size()) + " covariances");
  std::vector<size_t> order(ids.size());
  std::iota(order.begin(), order.end(), size_t{0});
  std::sort(order.begin(), order.end(), [&](size_t a, size_t b) { return ids[a] < ids[b]; });
  std::string text;
  char buffer[32];
  for (size_t k : order) {
    text += std::to_string(ids[k]);
    for (int r = 0; r < D; ++r)
      for (int c = r; c < D; ++c) {
        const auto end = std::to_chars(buffer, buffer + sizeof(buffer), covariances[k](r, c)).ptr;
        text.push_back(' ');
        text.append(buffer, end);
      }
    text.push_back('\n');
  }
  out << text;
}

template <class G>
std::vector<Eigen::Matrix<double, G::kDoF, G::kDoF>> batchCovariances(const PoseGraph<G>& graph,
                                                                      const std::vector<G>& poses) {
  if (static_cast<int>(poses.size()) != graph.numPoses())
    throw std::invalid_argument("batchCovariances: " + std::to_string(poses.size()) +
                                " poses for a graph of " + std::to_string(graph.numPoses()));
  std::vector<char> fixed(graph.numPoses(), 0);
  for (int v : graph.gaugeIndices()) fixed[v] = 1;
  SmootherOptions options;
  options.threads = 1;
  IncrementalSmoother<G> smoother(options);
  for (int v = 0; v < graph.numPoses(); ++v) {
    if (fixed[v])
      smoother.addFixedPose(poses[v]);
    else
      smoother.addPose(poses[v]);
  }
  for (const Factor<G>& f : factorsOf(graph)) smoother.addFactor(f);
  smoother.update();  // one elimination of the whole graph, linearised at `poses`
  return smoother.marginalCovariances();
}

template <class G>
void writeBatchCovariancesFile(const std::string& path, const PoseGraph<G>& graph,
                               const std::vector<G>& poses) {
  const auto covariances = batchCovariances(graph, poses);
  writeFile(path,
            [&](std::ostream& out) { writeCovariances<G::kDoF>(out, graph.ids, covariances); });
}

template <int D>
void writeCovariancesFile(const std::string& path, const std::vector<Key>& ids,
                          const std::vector<Eigen::Matrix<double, D, D>>& covariances) {
  writeFile(path, [&](std::ostream& out) { writeCovariances<D>(out, ids, covariances); });
}

template <class G>
void writeCovariancesFile(const std::string& path, const OnlineSmoother<G>& smoother) {
  writeCovariancesFile<G::kDoF>(path, smoother.ids(), smoother.smoother().marginalCovariances());
}

template void writeCovariances<3>(std::ostream&, const std::vector<Key>&,
                                  const std::vector<Eigen::Matrix<double, 3, 3>>&);
template void writeCovariances<6>(std::ostream&, const std::vector<Key>&,
                                  const std::vector<Eigen::Matrix<double, 6, 6>>&);
template std::vector<Eigen::Matrix<double, 3, 3>> batchCovariances(const PoseGraph2&,
                                                                   const std::vector<SE2>&);
template std::vector<Eigen::Matrix<double, 6, 6>> batchCovariances(const PoseGraph3&,
                                                                   const std::vector<SE3>&);
template void writeBatchCovariancesFile(const std::string&, const PoseGraph2&,
                                        const std::vector<SE2>&);
template void writeBatchCovariancesFile(const std::string&, const PoseGraph3&,
                                        const std::vector<SE3>&);
template void writeCovariancesFile<3>(const std::string&, const std::vector<Key>&,
                                      const std::vector<Eigen::Matrix<double, 3, 3>>&);
template void writeCovariancesFile<6>(const std::string&, const std::vector<Key>&,
                                      const std::vector<Eigen::Matrix<double, 6, 6>>&);
template void writeCovariancesFile(const std::string&, const OnlineSmoother2&);
template void writeCovariancesFile(const std::string&, const OnlineSmoother3&);

}  // namespace arbor::cli
