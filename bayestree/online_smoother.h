// The online layer over IncrementalSmoother: poses named by external ids (Key), edges arriving
// one at a time in any order. An edge to an unknown pose creates it from the known end composed
// with the measurement (or its inverse); an edge between two unknown poses is held (pending)
// until one end becomes known. The first pose ever seen is the fixed gauge pose.
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

struct OnlineStats {
  int poses = 0;
  int edges_accepted = 0;  ///< edges handed to the smoother (including released pending ones)
  int edges_duplicate = 0;
  int edges_pending = 0;  ///< currently held
  int edges_rejected = 0;
  int updates = 0;
  double total_update_time_s = 0;
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

  bool hasPose(Key id) const;
  /// The current estimate; throws std::out_of_range for an unknown id.
  G estimate(Key id) const;
  std::map<Key, G> estimates() const;  ///< every known pose (O(n))
  OnlineStats stats() const;
  const IncrementalSmoother<G>& smoother() const { return smoother_; }
  /// Dense smoother index → id.
  const std::vector<Key>& ids() const { return ids_; }

 private:
  struct Measurement {
    Key from, to;
    G z;
    Matrix omega;
  };
  bool sameMeasurement(const Measurement& a, const Measurement& b) const;
  int createPose(Key id, const G& value);
  /// Adds m to the smoother, creating its unknown end if any (returned in *created: true).
  bool apply(const Measurement& m, Key* created);
  void releasePending(Key known);

  OnlineSmootherOptions<G> options_;
  IncrementalSmoother<G> smoother_;
  std::unordered_map<Key, int> index_;
  std::vector<Key> ids_;
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
