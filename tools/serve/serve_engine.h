// The smoother behind `arbor serve`: an OnlineSmoother of the stream's dimension, with the
// estimate turned into Estimate values (every pose, or only those changed since the last one)
// and written as g2o, and a refine::BatchRefiner beside it (batch runs on snapshots in the
// background; reseeding goes through Estimate values so that the journal can hold them).
// Not thread-safe: the smoother thread owns it.
#pragma once

#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "arbor_slam/bayestree/online_smoother.h"
#include "arbor_slam/io/stream_measurements.h"
#include "arbor_slam/io/trajectory_writer.h"
#include "arbor_slam/tools/refine/batch_refiner.h"
#include "arbor_slam/tools/serve/stream_types.h"

namespace arbor::serve {

class Engine {
 public:
  virtual ~Engine() = default;
  virtual int dim() const = 0;
  /// Hands one validated edge to the smoother (the dimension must match).
  virtual EdgeResult add(const AnyStreamEdge& edge) = 0;
  /// Hands one validated prior to the smoother (OnlineSmoother::addPosePrior /
  /// addPositionPrior; the dimension must match).
  virtual EdgeResult addPrior(const AnyStreamPrior& prior) = 0;
  /// Hands one validated edge command to the smoother (OnlineSmoother::disableEdge /
  /// enableEdge; the next update applies it).
  virtual EdgeSwitchResult command(const StreamEdgeCommand& command) = 0;
  virtual UpdateStats update() = 0;
  /// SmootherOptions::solve_budget_mb: solves about `budget_mb` of the cliques the budget
  /// deferred (0: all; OnlineSmoother::solveDeferred), their poses marked changed for the next
  /// estimate(false).
  virtual void solveDeferred(double budget_mb) = 0;
  /// The cliques the budget left deferred (IncrementalSmoother::cliquesDeferred).
  virtual int cliquesDeferred() const = 0;
  /// Relinearises everything and iterates to convergence (OnlineSmoother::finalize), or until
  /// `cancel` (checked between iterations) is cancelled.
  virtual UpdateStats refine(const CancellationToken* cancel = nullptr) = 0;
  /// F over every factor not disabled (OnlineSmoother::objective).
  virtual double objective() const = 0;
  virtual OnlineStats stats() const = 0;
  /// With robust smoothing: every loop closure's weight and status (empty without it), and
  /// the threshold c² in use (0 without it).
  virtual std::vector<ClosureReport> closures() const = 0;
  virtual double inlierThreshold() const = 0;
  /// The estimate: every pose (`full`) or the poses whose value changed since the last call.
  /// F is filled (the objective) only for a full estimate, else NaN.
  virtual Estimate estimate(bool full) = 0;
  /// The marginal covariance of one pose (k×k) or the joint covariance of two (2k×2k) after the
  /// last update (OnlineSmoother::marginalCovariance / jointMarginalCovariance). Throws
  /// std::out_of_range for an unknown id, std::logic_error for a pose not through an update
  /// yet, std::invalid_argument for another count than 1 or 2.
  virtual Eigen::MatrixXd covariance(const std::vector<Key>& ids) const = 0;
  /// Writes the estimate and the edges applied so far but the disabled ones as g2o (the first
  /// pose is FIXed).
  virtual void writeG2o(const std::string& path) const = 0;
  /// As writeG2o in `format`; TUM's time of a pose is the utime (in seconds) of the edge or
  /// prior that created it.
  virtual void writeEstimate(const std::string& path, TrajectoryFormat format) const = 0;

  // Batch refinement (tools/refine/batch_refiner.h).
  virtual const refine::RefinerOptions& batchOptions() const = 0;
  /// Snapshots the smoother and starts a batch (solved at once when synchronous). False when
  /// one is in flight (counted as skipped) or the snapshot is too small.
  virtual bool startBatch(std::int64_t update) = 0;
  virtual void noteUpdate() = 0;  ///< an update ran (counted for a running batch)
  virtual bool batchInFlight() const = 0;
  virtual int batchesSkipped() const = 0;
  /// The batch in flight once finished (`wait`: waits for it); nullopt if none. With reseeding
  /// and a winning batch estimate, *seed gets the complete new linearisation point (every pose,
  /// a full Estimate; else num_poses = 0) for the caller to journal and apply with reseed().
  /// Rethrows a solver's exception.
  virtual std::optional<refine::BatchRun> collectBatch(bool wait, Estimate* seed) = 0;
  /// Rebuilds the smoother with the poses of `seed` (read back from its fields, so a journaled
  /// copy reproduces it bit for bit) as the linearisation point (OnlineSmoother::reseed).
  /// Throws std::invalid_argument on another dim, ragged arrays or an unknown id.
  /// The rebuild is kept only if it lowers F over everything the smoother holds.
  virtual ReseedResult reseed(const Estimate& seed) = 0;
};

/// An engine for 2D (SE2) or 3D (SE3) poses, with online robust smoothing when `robust` is
/// set; throws std::invalid_argument for another dim, batch.every < 0 or bad robust options.
std::unique_ptr<Engine> makeEngine(int dim, const SmootherOptions& options,
                                   const refine::RefinerOptions& batch = {},
                                   const std::optional<RobustOptions>& robust = std::nullopt);

}  // namespace arbor::serve
