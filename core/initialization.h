// Initial estimates for a pose graph: the odometry chain, a breadth-first spanning tree, and
// chordal relaxation (Carlone et al., "Initialization techniques for 3D SLAM", ICRA 2015).
//
// Common to all methods:
// - Each connected component (poses linked by edges) grows from its roots, whose values are
//   given (init_detail::findRoots):
//   · a component holding gauge poses (graph.gaugeIndices()): with graph.has_initial_estimate
//     every gauge pose is placed at its file value (graph.poses); without one, its first gauge
//     pose is placed at the value of a pose prior on it if there is one, else at the identity;
//   · a component anchored by its priors alone (no gauge pose): its lowest pose with a pose
//     prior, at that prior's value z·o⁻¹ (the prior is on x·o); without pose priors, its lowest
//     pose at the identity.
//   So with priors the guess is in the priors' frame.
// - A component rooted at the identity that has position priors is then moved rigidly onto them
//   (priors' frame): the weighted least-squares rigid alignment (Kabsch / Umeyama, weights the
//   isotropic precisions kDim / tr(Ω⁻¹)) of its poses' guessed positions onto the priors'
//   positions when those fix the rotation (≥ 2 distinct positions in 2D, ≥ 3 non-collinear in
//   3D: GaugeInformation), else the weighted mean translation alone.
// - A component that neither holds a gauge pose nor is anchored by its priors (possible only
//   when graph.fixed is set) gives std::invalid_argument naming its first pose id ("not
//   connected"); without graph.fixed every component has an anchor (PoseGraph::gaugeIndices).
// - Malformed graphs (edge, prior or gauge index out of range, graph.poses of the wrong size
//   while has_initial_estimate) give std::invalid_argument. Self-loop edges (i == j) are ignored.
#pragma once

#include <string>
#include <vector>

#include "arbor_slam/core/pose_graph.h"

namespace arbor {

enum class InitMethod { kOdometry, kSpanningTree, kChordal, kFile };

/// "odometry", "spanning-tree", "chordal", "file".
std::string toString(InitMethod method);
/// The inverse of toString; throws std::invalid_argument naming the value otherwise.
InitMethod parseInitMethod(const std::string& name);

/// The odometry chain: for k in dense-index order (ids ascending) xₖ = xₖ₋₁ · z, with z the
/// measurement of the first edge (file order) between k−1 and k, inverted if it goes k → k−1.
/// Every such chain link holds exactly in the result (except between two gauge poses).
/// A pose with no chain link to its predecessor (a gap in the ids, or an edges-only file
/// without odometry) starts a new chain segment: the segment is reached breadth-first from
/// the poses already placed, through the first edge met (poses in placement order, their
/// edges in file order), and the rest of the segment follows its own chain links.
template <class G>
std::vector<G> odometryInitialization(const PoseGraph<G>& graph);

/// Breadth-first spanning tree from the gauge: poses are taken in queue order, each pose's
/// edges in file order; an unplaced neighbour j of i gets xᵢ·z (edge i→j) or xᵢ·z⁻¹ (j→i).
/// O(n + m).
template <class G>
std::vector<G> spanningTreeInitialization(const PoseGraph<G>& graph);

/// Chordal relaxation. Rotations: min Σ κᵢⱼ ‖Rⱼ − Rᵢ Zᵢⱼ‖²_F over unconstrained d×d matrices
/// (gauge rotations fixed), κᵢⱼ the isotropic rotational precision r / tr(Ω_rr⁻¹) (as in
/// isotropicInformation), solved sparsely, each block then projected to SO(d).
/// Translations, rotations held: min Σ ‖tⱼ − tᵢ − Rᵢ t_z‖² weighted by the translational block
/// Ω_tt of each edge turned into the world frame, W = (Rᵢ Z) Ω_tt (Rᵢ Z)ᵀ (gauge fixed); when
/// every Ω_tt is τ I this is solved as one scalar system per coordinate (same result, faster).
/// Both systems are factored by CHOLMOD (supernodal LLᵀ). Exact for consistent measurements.
/// Throws std::runtime_error if a system cannot be solved.
template <class G>
std::vector<G> chordalInitialization(const PoseGraph<G>& graph);

/// Dispatch. kFile returns graph.poses (std::invalid_argument if !graph.has_initial_estimate).
template <class G>
std::vector<G> initialize(const PoseGraph<G>& graph, InitMethod method);

}  // namespace arbor
