// The online layer over IncrementalSmoother: poses named by external ids (Key), edges arriving
// one at a time in any order. An edge to an unknown pose creates it from the known end composed
// with the measurement (or its inverse); an edge between two unknown poses is held (pending)
// until one end becomes known. The first pose ever seen is the fixed gauge pose.
//
// Reseeding (reseed()) makes given values — typically a batch solver's estimate of a snapshot()
// — the linearisation point and rebuilds the Bayes tree from scratch; incremental updates then
// continue from there.
//
// Thread-safety: none. One thread owns an OnlineSmoother and makes every call (the LCM service
// feeds it from its single handler thread); const methods may run concurrently only with other
// const methods.
#pragma once

#include <map>
#include <string>
#include <unordered_map>
#include <vector>

#include <Eigen/Core>

#include "bayestree/incremental_smoother.h"
#include "core/pose_graph.h"

namespace arbor {

enum class EdgeStatus {
  kAccepted,   ///< added (to be used by the next update())
  kDuplicate,  ///< same ids, measurement and Ω as an accepted or pending edge: not added again
  kPending,    ///< both ends unknown: held until one end is known, then added
  kRejected,   ///< bad input; see reason
};

const char* toString(EdgeStatus status);

struct EdgeResult {
  EdgeStatus status = EdgeStatus::kAccepted;
  std::string reason;  ///< why it was rejected (or which edge it duplicates)
};

template <class G>
struct OnlineSmootherOptions {
  SmootherOptions smoother;
  G gauge = G::Identity();  ///< the value of the first pose seen (held fixed)
};

/// What reseed() did.
struct ReseedResult {
  bool applied = false;  ///< the rebuilt smoother replaced the old one
  double F_before = 0;   ///< F over every factor at the estimate before
  double F_rebuilt = 0;  ///< F over every factor at the rebuilt estimate
  UpdateStats stats;     ///< of the rebuild's update; time_s: the whole rebuild
};

struct OnlineStats {
  int poses = 0;
  int edges_accepted = 0;  ///< edges handed to the smoother (including released pending ones)
  int edges_duplicate = 0;
  int edges_pending = 0;  ///< currently held
  int edges_rejected = 0;
  int updates = 0;
  double total_update_time_s = 0;
  int reseeds = 0;  ///< rebuilds by reseed() that were kept
  double total_reseed_time_s = 0;
  UpdateStats last_update;
};

template <class G>
class OnlineSmoother {
 public:
  static constexpr int kDoF = G::kDoF;
  using Matrix = Eigen::Matrix<double, kDoF, kDoF>;

  explicit OnlineSmoother(OnlineSmootherOptions<G> options = {});

  /// One measurement z of pose `to` in the frame of pose `from`, with information Ω.
  EdgeResult addEdge(Key from, Key to, const G& z, const Matrix& omega);
  /// Runs one incremental update over the edges accepted since the last one.
  UpdateStats update();
  /// Relinearises everything and iterates to convergence (the end of a replay).
  UpdateStats finalize();

  /// The poses known at the last update() (the first ones in dense order; the gauge first and
  /// listed in `fixed`), every edge taken in by the smoother so far, and the current estimate as
  /// `poses`: a connected problem for a batch solver (ids in dense order, not sorted).
  PoseGraph<G> snapshot() const;

  /// The complete linearisation point reseed(values) would use, in dense order:
  /// - poses in `values` take those values, all moved by the one rigid transform that puts the
  ///   gauge pose's value onto its current (fixed) value when the gauge is in `values` (else
  ///   they are taken as they are);
  /// - any other pose keeps its current estimate relative to the pose it was created from
  ///   (x_k = x'_c · x_c⁻¹ · x_k, creators first), so poses that arrived after a snapshot move
  ///   rigidly with their creator instead of being dead-reckoned again.
  /// Throws std::invalid_argument naming the id for an unknown pose or a non-finite value.
  std::vector<G> seedPoint(const std::map<Key, G>& values) const;
  /// As above with the values of the first `prefix.size()` poses in dense order (as snapshot()
  /// lists them); throws std::invalid_argument if there are more than the known poses.
  std::vector<G> seedPoint(const std::vector<G>& prefix) const;
  /// Rebuilds the smoother with seedPoint(values) as its linearisation point (the gauge pose keeps
  /// its fixed value): every factor, including those accepted since the last update(), is
  /// re-added and one update eliminates the whole tree, so the estimate afterwards is one
  /// Gauss–Newton step from the seed (equal to it when the seed is the optimum). With
  /// `only_if_lower` the rebuilt smoother is kept only when its F over every factor is lower
  /// than the current one (a batch estimate of an older snapshot can be worse for the poses
  /// and edges that came since). Throws as seedPoint(); on a throw nothing changed.
  ReseedResult reseed(const std::map<Key, G>& values, bool only_if_lower = false);
  ReseedResult reseed(const std::vector<G>& prefix, bool only_if_lower = false);

  bool hasPose(Key id) const;
  /// The current estimate; throws std::out_of_range for an unknown id.
  G estimate(Key id) const;
  std::map<Key, G> estimates() const;  ///< every known pose (O(n))
  OnlineStats stats() const;
  const IncrementalSmoother<G>& smoother() const { return smoother_; }
  /// Dense smoother index → id.
  const std::vector<Key>& ids() const { return ids_; }

 private:
  /// Bookkeeping after an update() or finalize() of the smoother.
  UpdateStats recordUpdate(const UpdateStats& s);
  struct Measurement {
    Key from, to;
    G z;
    Matrix omega;
  };
  bool sameMeasurement(const Measurement& a, const Measurement& b) const;
  int createPose(Key id, const G& value, int creator);
  /// Adds m to the smoother, creating its unknown end if any (returned in *created: true).
  bool apply(const Measurement& m, Key* created);
  void releasePending(Key known);
  std::vector<G> completeSeed(std::vector<G> values, const std::vector<char>& given) const;
  ReseedResult rebuild(const std::vector<G>& seed, bool only_if_lower);

  OnlineSmootherOptions<G> options_;
  IncrementalSmoother<G> smoother_;
  std::unordered_map<Key, int> index_;
  std::vector<Key> ids_;
  std::vector<int> creator_;  ///< per dense index: the known end it was created from (−1: gauge)
  std::vector<RelativePoseEdge<G>> queued_;  ///< handed to the smoother since the last update
  int poses_at_update_ = 0;                  ///< poses known at the last update
  std::map<std::pair<Key, Key>, std::vector<Measurement>> seen_;  ///< accepted and pending
  std::vector<Measurement> pending_;
  std::vector<char> pending_alive_;
  std::unordered_map<Key, std::vector<int>> pending_by_key_;
  OnlineStats stats_;
};

using OnlineSmoother2 = OnlineSmoother<SE2>;
using OnlineSmoother3 = OnlineSmoother<SE3>;

extern template class OnlineSmoother<SE2>;
extern template class OnlineSmoother<SE3>;

}  // namespace arbor
