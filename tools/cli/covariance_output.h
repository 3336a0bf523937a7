// Marginal covariances of every pose as a text file (docs/files.md, "Covariances"): one line per
// pose by ascending id, `id c11 c12 … c1k c22 … ckk`, the upper triangle of its k×k covariance
// (k = 3 in 2D, 6 in 3D) row by row, in the tangent order [translation; rotation] of the
// smoother's retraction x ⊞ τ. For `arbor batch --covariances` and, through
// writeCovariancesFile(path, smoother), a replay's final smoother.
#pragma once

#include <iosfwd>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "arbor_slam/bayestree/online_smoother.h"
#include "arbor_slam/core/pose_graph.h"

namespace arbor::cli {

/// covariances[k] of id ids[k], written by ascending id.
template <int D>
void writeCovariances(std::ostream& out, const std::vector<Key>& ids,
                      const std::vector<Eigen::Matrix<double, D, D>>& covariances);

/// Every pose's marginal covariance at `poses` (the graph's dense order), in the graph's gauge
/// (gaugeIndices(): those poses are constants, with zero covariance): the Bayes tree of the
/// system linearised there (one IncrementalSmoother update with every factor), walked once.
template <class G>
std::vector<Eigen::Matrix<double, G::kDoF, G::kDoF>> batchCovariances(const PoseGraph<G>& graph,
                                                                      const std::vector<G>& poses);

/// As batchCovariances, written to `path`; throws std::runtime_error if it cannot be written.
template <class G>
void writeBatchCovariancesFile(const std::string& path, const PoseGraph<G>& graph,
                               const std::vector<G>& poses);

/// covariances[k] of id ids[k], written to `path` by ascending id; throws std::runtime_error if
/// it cannot be written.
template <int D>
void writeCovariancesFile(const std::string& path, const std::vector<Key>& ids,
                          const std::vector<Eigen::Matrix<double, D, D>>& covariances);

/// Every known pose of `smoother` (its linear system after the last update or finalize), by id,
/// to `path` (what `arbor replay --covariances` writes, from ReplayResult::covariances). Throws
/// std::runtime_error if it cannot be written, std::logic_error if a pose has not been through
/// update() yet.
template <class G>
void writeCovariancesFile(const std::string& path, const OnlineSmoother<G>& smoother);

}  // namespace arbor::cli
