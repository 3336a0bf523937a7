// The Gauss–Newton normal equations H δ = −g of a pose graph, H = Σ AᵀA and g = Aᵀr summed
// block by block over the whitened linearisations of its edges, priors and custom factors (a
// binary custom factor enters as an edge, a unary one as a prior; a prior is unary:
// its AᵀA goes into one diagonal block and Aᵀr into one segment of g; a prior on a gauge pose
// adds a constant to F and nothing else), with the block pattern, a
// fill-reducing block ordering and the symbolic factorisation computed once (Dellaert & Kaess,
// "Square Root SAM", IJRR 2006, §3–4). The numeric factorisation is BlockCholesky (fixed-size
// blocks) up to ~1e8 flops and CHOLMOD's supernodal LLᵀ beyond.
#pragma once

#include <memory>
#include <string>
#include <utility>
#include <vector>

#include <Eigen/Core>

#include "arbor_slam/core/block_cholesky.h"
#include "arbor_slam/core/pose_graph.h"
#include "arbor_slam/core/sparse_cholesky.h"

namespace arbor {

/// Why the gauge leaves the problem singular, or "" when it does not: every connected component
/// of the graph (poses linked by edges) must be anchored, by holding a gauge pose
/// (graph.gaugeIndices()) or by priors that fix its gauge (core/gauge.h GaugeInformation); the
/// message names the first pose of the first component that is not. Also checks the edge,
/// prior and gauge indices (throws std::invalid_argument when one is out of range).
template <class G>
std::string gaugeProblem(const PoseGraph<G>& graph);

/// Which sparse Cholesky factors H.
enum class CholeskyBackend {
  kAuto,     ///< BlockCholesky below kBlockCholeskyMaxFlops per factorisation, else CHOLMOD
  kBlock,    ///< BlockCholesky
  kCholmod,  ///< CHOLMOD (supernodal or simplicial, its choice)
};
/// Where kAuto switches to CHOLMOD, whose supernodal BLAS-3 kernels win on large dense fronts.
/// Measured per factorisation with Debian's OpenBLAS at one thread (`arbor bench growth`,
/// docs/design.md): BlockCholesky is 2–3× faster below ~2e7 flops (garage, M3500, intel); the
/// crossover lies between 4e7 and 2e8 (BlockCholesky's time over CHOLMOD's: torus3D 0.71 at
/// 43 MFlop and 1.07 at 182 MFlop, sphere_bignoise 1.37 at 55 MFlop); beyond, CHOLMOD is up to
/// 1.9× faster (sphere_bignoise 535 MFlop, torus3D 1 GFlop). The first tuning (2e9) was done
/// with ATLAS.
inline constexpr double kBlockCholeskyMaxFlops = 1e8;

/// Normal equations over the non-gauge poses (the variables) of one graph. The variables are
/// numbered in a fill-reducing order; vectors over them (gradient, steps) have kDoF entries per
/// variable in that order. The graph must outlive this object.
template <class G>
class NormalEquations {
 public:
  static constexpr int kDoF = G::kDoF;
  using Block = Eigen::Matrix<double, kDoF, kDoF>;
  using Vector = Eigen::Matrix<double, kDoF, 1>;

  /// Computes the variables, the ordering, the pattern of H and its symbolic factorisation.
  /// Throws std::invalid_argument on out-of-range pose or gauge indices.
  explicit NormalEquations(const PoseGraph<G>& graph,
                           CholeskyBackend backend = CholeskyBackend::kAuto);
  ~NormalEquations();

  /// Number of scalar unknowns (kDoF × non-gauge poses).
  int dimension() const { return num_variables_ * kDoF; }
  /// The backend in use (never kAuto).
  CholeskyBackend backend() const { return backend_; }
  /// Flops of one factorisation (from the symbolic analysis of the block pattern).
  double factorizationFlops() const { return flops_; }
  /// Scalar nonzeros of H's upper triangle and of the Cholesky factor.
  double hessianNonzeros() const;
  double factorNonzeros() const;

  /// Linearises every edge and prior at `poses` and assembles H and g; returns F = Σ‖r‖² there
  /// (priors on gauge poses included). With edge weights set, edge k's whitened A and r are
  /// scaled by √w_k first (iteratively reweighted least squares), so H = Σ w AᵀA, g = Σ w Aᵀr
  /// and the value returned is Σ w_k ‖r_k‖² + the priors' Σ‖r‖².
  double linearize(const std::vector<G>& poses);

  /// Per-edge weights w_k ≥ 0 (one per graph edge, in edge order; the vector must outlive this
  /// object's use of it), or null for none: the unweighted path, bit for bit. Priors are never
  /// weighted. Throws std::invalid_argument on a size mismatch.
  void setEdgeWeights(const std::vector<double>* weights);
  const std::vector<double>* edgeWeights() const { return edge_weights_; }

  /// g = Aᵀr at the last linearisation (F's gradient is 2g).
  const Eigen::VectorXd& gradient() const { return gradient_; }
  /// diag(H) at the last linearisation.
  const Eigen::VectorXd& hessianDiagonal() const { return hessian_diagonal_; }

  /// Factors H + diag(damping) (no damping when null). False if not positive definite.
  bool factorize(const Eigen::VectorXd* damping = nullptr);
  /// Why the last factorisation failed (naming the pose), or "".
  std::string factorizationFailure() const;
  /// x = (H + diag(damping))⁻¹ b with the last successful factorisation.
  void solve(const Eigen::VectorXd& b, Eigen::VectorXd* x);

  /// The linear model ‖r + A δ‖² at the last linearisation (edges and priors).
  double modelCost(const Eigen::VectorXd& delta) const;
  /// ‖A v‖² = vᵀ H v at the last linearisation.
  double jacobianSquaredNorm(const Eigen::VectorXd& v) const;

  /// out[k] = poses[k] ⊞ δ_k (gauge poses copied).
  void retract(const std::vector<G>& poses, const Eigen::VectorXd& delta,
               std::vector<G>* out) const;
  /// δ per pose (zero for gauge poses), in pose order.
  std::vector<typename G::Tangent> perPose(const Eigen::VectorXd& delta) const;

 private:
  // Where an edge's terms go: variable (block) indices, −1 for a gauge pose, and its
  // off-diagonal block of H (−1 if none), stored below the diagonal: H(high, low).
  struct EdgeSlot {
    int var_i = -1;
    int var_j = -1;
    int off_diagonal = -1;
    bool i_is_high = false;  // var_i > var_j: the block is A_iᵀA_j (else A_jᵀA_i)
  };
  struct EdgeLinearization {
    Block A_i, A_j;
    Vector r;
  };
  // A unary prior's whitened linearisation (kRows residual rows) and its variable (−1: gauge).
  template <int kRows>
  struct PriorLinearization {
    Eigen::Matrix<double, kRows, kDoF> A;
    Eigen::Matrix<double, kRows, 1> r;
    int var = -1;
  };
  using PosePriorLinearization = PriorLinearization<kDoF>;
  using PositionPriorLinearization = PriorLinearization<G::kDim>;
  struct OffDiagonalBlock {
    int high = 0, low = 0;  // the block H(high, low), high > low
  };
  using Blocks = std::vector<Block, Eigen::aligned_allocator<Block>>;

  void setUpCholmod();
  void slotFor(int i, int j, const std::vector<std::pair<int, int>>& pairs, EdgeSlot* s) const;
  // H and g += one binary term's AᵀA and Aᵀr (an edge, or a custom factor with var_j −1 if
  // unary).
  void addTerms(const EdgeSlot& s, const EdgeLinearization& lin);
  double slotModelCost(const std::vector<EdgeSlot>& slots,
                       const std::vector<EdgeLinearization>& lin, const Eigen::VectorXd& delta,
                       bool with_residual) const;
  template <class Prior, class Linearization>
  double linearizePriors(const std::vector<Prior>& priors, const std::vector<G>& poses,
                         std::vector<Linearization>* out);
  template <class Linearization>
  double priorModelCost(const std::vector<Linearization>& lin, const Eigen::VectorXd& delta,
                        bool with_residual) const;
  void loadCholmod(const Eigen::VectorXd* damping);
  void loadBlocks(const Eigen::VectorXd* damping);

  const PoseGraph<G>& graph_;
  const std::vector<double>* edge_weights_ = nullptr;
  CholeskyBackend backend_ = CholeskyBackend::kBlock;
  double flops_ = 0.0;
  int num_variables_ = 0;
  std::vector<int> var_of_pose_;  // −1 for gauge poses
  std::vector<int> pose_of_var_;
  std::vector<EdgeSlot> slots_;
  std::vector<OffDiagonalBlock> off_diagonal_;
  std::vector<EdgeLinearization> linearization_;
  std::vector<PosePriorLinearization> pose_prior_linearization_;
  std::vector<PositionPriorLinearization> position_prior_linearization_;
  std::vector<EdgeSlot> custom_slots_;  // var_j −1 for a unary custom factor
  std::vector<EdgeLinearization> custom_linearization_;
  Blocks diagonal_blocks_;      // H(j, j)
  Blocks off_diagonal_blocks_;  // H(row, col), one per OffDiagonalBlock
  Eigen::VectorXd gradient_;
  Eigen::VectorXd hessian_diagonal_;
  int failed_column_ = -1;
  // BlockCholesky: the position of each off-diagonal block of H in L.
  std::unique_ptr<BlockCholesky<kDoF>> block_cholesky_;
  std::vector<int> block_position_;
  // CHOLMOD: H's upper triangle in compressed-column form. Off-diagonal block b sits in block
  // column high as H(low, high) = H(high, low)ᵀ: its entry (r, c) is
  // values_[col_ptr_[high·kDoF + c] + row_offset_[b] + r].
  std::unique_ptr<SparseCholesky> cholmod_;
  std::vector<int> col_ptr_;
  std::vector<int> row_offset_;
  std::vector<double> values_;
};

}  // namespace arbor
