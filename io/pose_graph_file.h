// Reading and writing pose-graph files: g2o (VERTEX_SE2 / EDGE_SE2, VERTEX_SE3:QUAT /
// EDGE_SE3:QUAT, FIX; the priors EDGE_PRIOR_SE2, EDGE_PRIOR_SE2_XY, EDGE_SE3_PRIOR with its
// PARAMS_SE3OFFSET, EDGE_SE3_XYZ_PRIOR), our POSITION_PRIOR2 / POSITION_PRIOR3, and TORO
// (VERTEX2 / EDGE2). docs/files.md lists every record's fields. Every malformed line is a
// FileError naming "path:line: what was wrong"; information matrices that are not positive
// definite are refused, repaired or made isotropic according to ReadOptions, edges and priors
// alike.
#pragma once

#include <iosfwd>
#include <stdexcept>
#include <string>
#include <variant>
#include <vector>

#include "arbor_slam/core/information.h"
#include "arbor_slam/core/pose_graph.h"

namespace arbor {

using AnyPoseGraph = std::variant<PoseGraph2, PoseGraph3>;

struct ReadOptions {
  InformationPolicy information = InformationPolicy::kRefuse;
};

struct ReadReport {
  int repaired = 0;  ///< Ω that were not positive definite, replaced by nearestPositiveDefinite
                     ///< (kRepair, and kIsotropic before the isotropic form is taken)
  int made_isotropic = 0;  ///< Ω replaced by its isotropic form (kIsotropic: every edge and
                           ///< prior; a position prior's Ω becomes τ I, τ = d / tr(Ω⁻¹))
  std::vector<int> edge_lines;            ///< 1-based source line of each edge in graph.edges
  std::vector<int> pose_prior_lines;      ///< … of each prior in graph.pose_priors
  std::vector<int> position_prior_lines;  ///< … of each prior in graph.position_priors
  std::vector<std::string> warnings;      ///< "path:line: …", e.g. a quaternion renormalised
};

/// A malformed or unreadable file; what() = "path:line: message" (or "path: message").
class FileError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

/// Reads a g2o or TORO file. Dense pose indices follow ascending ids. Without VERTEX lines the
/// poses are Identity and has_initial_estimate is false. Throws FileError.
AnyPoseGraph readPoseGraphFile(const std::string& path, const ReadOptions& options = {},
                               ReadReport* report = nullptr);

/// As readPoseGraphFile, from a stream; `name` is used in messages in place of the path.
AnyPoseGraph readPoseGraph(std::istream& in, const std::string& name,
                           const ReadOptions& options = {}, ReadReport* report = nullptr);

/// Writes g2o: VERTEX lines of `poses` (one per graph id), FIX lines for graph.fixed, then EDGE
/// lines, every number in its shortest exactly-round-tripping form. G is SE2 or SE3. A graph
/// with priors also gets them after the edges, as g2o's tags (EDGE_PRIOR_SE2 and
/// EDGE_PRIOR_SE2_XY; EDGE_SE3_PRIOR and EDGE_SE3_XYZ_PRIOR), and in 3D the PARAMS_SE3OFFSET
/// lines they name first of all (id 0 the identity, then each distinct offset); a graph without
/// priors is written as before.
/// Throws std::invalid_argument if poses do not match the graph, a value is not finite or the
/// graph holds custom factors (g2o has no tag for them; the message names the first).
template <class G>
void writeG2o(std::ostream& out, const PoseGraph<G>& graph, const std::vector<G>& poses);

/// As writeG2o, to a file; throws FileError if it cannot be written.
template <class G>
void writeG2oFile(const std::string& path, const PoseGraph<G>& graph, const std::vector<G>& poses);

}  // namespace arbor
