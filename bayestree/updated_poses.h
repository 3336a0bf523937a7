// The poses an update changed (IncrementalSmoother::updatedPoses): those moved since the last
// update (transformPoses) and those its solve touched, each listed once, or every variable
// after a step that set Δ everywhere (dogleg, relinearizeAll, a swapped-in tree). Sorted when
// first asked for, not by every update: a replay never asks, and sorting a few hundred solved
// poses an update was 4% of intel's update instructions.
//
// Invariants: between begin() and finish(), a pose is in the list at most once (its stamp is
// the update's); after finish(), inOrder() lists them in increasing order.
#pragma once

#include <algorithm>
#include <utility>
#include <vector>

namespace arbor::bayestree {

class UpdatedPoses {
 public:
  /// A new pose, listed by no update yet.
  void addPose() { stamp_.push_back(0); }
  /// Poses moved now: listed by the next update.
  void moved(const std::vector<int>& poses) {
    moved_.insert(moved_.end(), poses.begin(), poses.end());
  }
  /// Starts an update's list with the poses moved since the last one.
  void begin() {
    ++update_;
    list_.clear();
    all_ = false;
    for (int v : moved_) note(v);
    moved_.clear();
  }
  /// Pose v changed in this update.
  void note(int v) {
    if (stamp_[v] == update_) return;
    stamp_[v] = update_;
    list_.push_back(v);
  }
  /// Every variable changed in this update.
  void noteAll() { all_ = true; }
  /// Ends the update's list; with noteAll, every pose not `fixed`.
  void finish(const std::vector<char>& fixed) {
    if (all_) {
      list_.clear();
      for (int v = 0; v < static_cast<int>(fixed.size()); ++v)
        if (!fixed[v]) list_.push_back(v);
    }
    sorted_ = all_;  // the loop above lists them in order
  }
  /// What an update that is then undone (IncrementalSmoother's guarded update) restores: the
  /// last update's list and the poses moved since (O(their number), not O(poses)).
  struct Saved {
    std::vector<int> list, moved;
    bool all = false, sorted = true;
  };
  Saved save() const { return {list_, moved_, all_, sorted_}; }
  void restore(Saved&& s) {
    list_ = std::move(s.list);
    moved_ = std::move(s.moved);
    all_ = s.all;
    sorted_ = s.sorted;
  }
  /// The last update's poses, in increasing order (sorted once per update).
  const std::vector<int>& inOrder() const {
    if (!sorted_) {
      std::sort(list_.begin(), list_.end());
      sorted_ = true;
    }
    return list_;
  }

 private:
  mutable std::vector<int> list_;
  std::vector<int> moved_, stamp_;
  int update_ = 0;
  bool all_ = false;
  mutable bool sorted_ = true;
};

}  // namespace arbor::bayestree
