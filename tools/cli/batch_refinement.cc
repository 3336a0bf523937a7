#include "tools/cli/batch_refinement.h"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <exception>
#include <map>
#include <memory>
#include <numeric>
#include <stdexcept>
#include <thread>

#include "bayestree/incremental_smoother.h"
#include "bayestree/online_smoother.h"
#include "core/riemannian_staircase.h"
#include "tools/cli/cli_common.h"
#include "tools/cli/replay_order.h"

namespace arbor::cli {

BatchKind parseBatchKind(const std::string& name) {
  if (name == "lm") return BatchKind::kLm;
  if (name == "rtr") return BatchKind::kRtr;
  throw std::invalid_argument("--batch must be lm or rtr, not '" + name + "'");
}

std::string toString(BatchKind kind) { return kind == BatchKind::kLm ? "lm" : "rtr"; }

namespace {

/// The online layer's rules over an IncrementalSmoother indexed by creation order, with the
/// provenance of every created pose kept so that it can be rebuilt from other initial values.
template <class G>
class LoopSmoother {
 public:
  LoopSmoother(const PoseGraph<G>& graph, const SmootherOptions& options)
      : graph_(graph), smoother_(options), slot_(graph.numPoses(), -1) {}

  /// Feeds graph edge `e`; returns its status and counts it.
  EdgeStatus add(int e, std::string* reason) {
    const auto& edge = graph_.edges[e];
    if (edge.i == edge.j) {
      *reason = "self-loop on pose " + std::to_string(graph_.ids[edge.i]);
      return EdgeStatus::kRejected;
    }
    auto& same = seen_[{edge.i, edge.j}];
    for (int other : same) {
      const auto& o = graph_.edges[other];
      if (o.information == edge.information &&
          o.measurement.localCoordinates(edge.measurement).norm() == 0.0) {
        *reason = "duplicates edge " + std::to_string(other);
        return EdgeStatus::kDuplicate;
      }
    }
    same.push_back(e);
    if (node_.empty()) create(edge.i, G::Identity(), {-1, -1, true});  // first pose: the gauge
    if (slot_[edge.i] < 0 && slot_[edge.j] < 0) {
      pending_.push_back(e);
      return EdgeStatus::kPending;
    }
    std::vector<int> work;
    apply(e, &work);
    while (!work.empty()) {  // release edges held for a pose that now exists (iteratively)
      const int known = work.back();
      work.pop_back();
      for (size_t p = 0; p < pending_.size(); ++p) {
        const auto& held = graph_.edges[pending_[p]];
        if (held.i != known && held.j != known) continue;
        const int released = pending_[p];
        pending_.erase(pending_.begin() + static_cast<long>(p));
        --p;
        apply(released, &work);
      }
    }
    return EdgeStatus::kAccepted;
  }

  UpdateStats update() { return smoother_.update(); }
  UpdateStats finalize() { return smoother_.relinearizeAll(); }
  const IncrementalSmoother<G>& smoother() const { return smoother_; }
  int pending() const { return static_cast<int>(pending_.size()); }

  /// The known poses and accepted edges (smoother order; the first pose fixed).
  PoseGraph<G> snapshot(std::vector<G>* estimate) const {
    PoseGraph<G> snap;
    for (size_t k = 0; k < node_.size(); ++k) {
      snap.ids.push_back(graph_.ids[node_[k]]);
      snap.index[snap.ids.back()] = static_cast<int>(k);
    }
    snap.edges = smoother_.factors();
    snap.poses = smoother_.estimate();
    snap.fixed = {0};
    snap.has_initial_estimate = true;
    *estimate = snap.poses;
    return snap;
  }

  /// Rebuilds the smoother with the first `seed.size()` poses starting at `seed` (moved into the
  /// frame of the fixed pose) and later poses composed from them through the edges that created
  /// them (the measurement, or with `relative_to_current` the current incremental estimate
  /// relative to the creator); re-adds every factor and updates once.
  UpdateStats reseed(const std::vector<G>& seed, bool relative_to_current) {
    if (seed.empty() || seed.size() > node_.size()) {
      throw std::invalid_argument("reseed: " + std::to_string(seed.size()) + " poses for " +
                                  std::to_string(node_.size()));
    }
    std::vector<G> values(node_.size());
    const std::vector<G> current = smoother_.estimate();
    const G anchor = current[0].compose(seed[0].inverse());
    for (size_t k = 0; k < node_.size(); ++k) {
      if (k < seed.size()) {
        values[k] = anchor.compose(seed[k]);
      } else if (relative_to_current) {  // keep the incremental pose relative to its creator
        const int parent = origin_[k].parent;
        values[k] = values[parent].compose(current[parent].inverse().compose(current[k]));
      } else {  // as the online layer creates a pose: its creator composed with the measurement
        const Origin& o = origin_[k];
        const G& z = graph_.edges[o.edge].measurement;
        values[k] = values[o.parent].compose(o.forward ? z : z.inverse());
      }
    }
    values[0] = smoother_.estimate(0);
    IncrementalSmoother<G> fresh(smoother_.options());
    fresh.addFixedPose(values[0]);
    for (size_t k = 1; k < values.size(); ++k) fresh.addPose(values[k]);
    for (const auto& f : smoother_.factors()) fresh.addFactor(f);
    smoother_ = std::move(fresh);
    return smoother_.update();
  }

  /// The estimate in the graph's dense order (poses never reached keep their graph value).
  std::vector<G> graphEstimate() const {
    std::vector<G> poses = graph_.poses;
    const std::vector<G> all = smoother_.estimate();
    for (size_t k = 0; k < node_.size(); ++k) poses[node_[k]] = all[k];
    return poses;
  }
  /// Smoother-order poses → graph order (poses not in `poses` keep their graph value).
  std::vector<G> toGraphOrder(const std::vector<G>& poses) const {
    std::vector<G> out = graph_.poses;
    for (size_t k = 0; k < poses.size(); ++k) out[node_[k]] = poses[k];
    return out;
  }

 private:
  struct Origin {
    int parent = -1;      ///< smoother index of the known end
    int edge = -1;        ///< graph edge that created the pose
    bool forward = true;  ///< parent ∘ z (else parent ∘ z⁻¹)
  };

  int create(int node, const G& value, Origin origin) {
    const int k = node_.empty() ? smoother_.addFixedPose(value) : smoother_.addPose(value);
    slot_[node] = k;
    node_.push_back(node);
    origin_.push_back(origin);
    return k;
  }

  /// Adds edge e (at least one end known); a created end is pushed to *work.
  void apply(int e, std::vector<int>* work) {
    const auto& edge = graph_.edges[e];
    int a = slot_[edge.i], b = slot_[edge.j];
    if (b < 0) {
      b = create(edge.j, smoother_.estimate(a).compose(edge.measurement), {a, e, true});
      work->push_back(edge.j);
    } else if (a < 0) {
      a = create(edge.i, smoother_.estimate(b).compose(edge.measurement.inverse()), {b, e, false});
      work->push_back(edge.i);
    }
    auto factor = edge;
    factor.i = a;
    factor.j = b;
    smoother_.addFactor(factor);
  }

  const PoseGraph<G>& graph_;
  IncrementalSmoother<G> smoother_;
  std::vector<int> slot_;  ///< graph index → smoother index (−1: unknown)
  std::vector<int> node_;  ///< smoother index → graph index
  std::vector<Origin> origin_;
  std::vector<int> pending_;
  std::map<std::pair<int, int>, std::vector<int>> seen_;
};

template <class G>
double rotationAngle(const G& a, const G& b) {
  const Eigen::Matrix<double, G::kDim, G::kDim> r = a.rotation().transpose() * b.rotation();
  const double c = std::clamp((r.trace() - (G::kDim - 2)) / 2.0, -1.0, 1.0);
  return std::acos(c);  // SO(2): tr = 2cosθ; SO(3): tr = 1 + 2cosθ
}

/// Solves `snap` from `incremental` and fills the run's figures (any thread).
template <class G>
void solveSnapshot(BatchKind kind, const PoseGraph<G>& snap, const std::vector<G>& incremental,
                   std::vector<G>* batch, BatchRun* run) {
  run->poses = snap.numPoses();
  run->edges = snap.numEdges();
  Stopwatch clock;
  if (kind == BatchKind::kLm) {
    *batch = incremental;
    run->iterations = solveBatch(snap, batch).iterations;
  } else {
    batch->assign(incremental.size(), G::Identity());
    const RtrSummary s = solveRtr(snap, batch);
    run->rank = s.rank;
    run->lambda_min = s.lambda_min;
    run->certified = s.certified;
    run->iterations = s.rtr_iterations;
  }
  run->time_s = clock.seconds();
  run->F_incremental = objective(snap, incremental);
  run->F_batch = objective(snap, *batch);
  run->relative_gap = (run->F_incremental - run->F_batch) / std::max(run->F_batch, 1e-300);
  run->margin = std::abs(run->F_incremental - run->F_batch);
  run->winner = run->margin <= 1e-9 * std::max(run->F_incremental, run->F_batch) ? "tie"
                : run->F_batch < run->F_incremental                              ? "batch"
                                                                                 : "incremental";
  const G inc0 = incremental[0].inverse(), bat0 = (*batch)[0].inverse();
  for (size_t k = 0; k < incremental.size(); ++k) {
    const G a = inc0.compose(incremental[k]), b = bat0.compose((*batch)[k]);
    run->max_translation_diff =
        std::max(run->max_translation_diff, (a.translation() - b.translation()).norm());
    run->max_rotation_diff = std::max(run->max_rotation_diff, rotationAngle(a, b));
  }
}

template <class G>
struct InFlight {
  PoseGraph<G> snap;
  std::vector<G> incremental, batch;
  BatchRun run;
  std::exception_ptr error;
  std::atomic<bool> done{false};
  std::thread thread;
  ~InFlight() {
    if (thread.joinable()) thread.join();
  }
};

}  // namespace

template <class G>
LoopResult<G> runReplayWithBatches(const PoseGraph<G>& graph, const ReplaySettings& settings,
                                   const BatchLoopSettings& loop) {
  if (loop.every < 0) {
    throw std::invalid_argument("--batch-every must be >= 0, not " + std::to_string(loop.every));
  }
  LoopSmoother<G> smoother(graph, settings.smoother);
  LoopResult<G> result;
  ReplayResult<G>& r = result.replay;
  std::unique_ptr<InFlight<G>> flight;

  // Joins a finished (or, with `wait`, any) batch, records it and reseeds if it won.
  auto collect = [&](bool wait, UpdateRow* row) {
    if (!flight || (!wait && !flight->done.load())) return;
    if (flight->thread.joinable()) flight->thread.join();
    if (flight->error) std::rethrow_exception(flight->error);
    BatchRun run = flight->run;
    if (loop.reseed && run.winner == "batch") {
      run.F_before_reseed = smoother.smoother().objective();
      Stopwatch clock;
      const UpdateStats s = smoother.reseed(flight->batch, loop.reseed_relative);
      run.reseeded = true;
      run.reseed_s = clock.seconds();
      run.F_after_reseed = smoother.smoother().objective();
      run.reseed_update = static_cast<int>(r.rows.size());
      r.relinearized += s.variables_relinearized;
      r.indeterminate += s.indeterminate_cliques;
      if (row) row->latency_ms += 1e3 * run.reseed_s;
      ++result.reseeds;
      result.reseed_s += run.reseed_s;
    }
    result.batches.push_back(run);
    flight.reset();
  };

  const std::vector<std::vector<int>> groups = replayGroups(graph, settings.per_pose);
  r.rows.reserve(groups.size());
  int fed = 0;
  for (const auto& group : groups) {
    for (int e : group) {
      std::string reason;
      const EdgeStatus status = smoother.add(e, &reason);
      if (status == EdgeStatus::kDuplicate) ++r.duplicates;
      if (status == EdgeStatus::kRejected) {
        ++r.rejected;
        r.rejections.push_back("edge " + std::to_string(graph.ids[graph.edges[e].i]) + " -> " +
                               std::to_string(graph.ids[graph.edges[e].j]) +
                               " rejected: " + reason);
      }
    }
    fed += static_cast<int>(group.size());
    const bool running = flight && !flight->done.load();
    Stopwatch clock;
    const UpdateStats s = smoother.update();
    const double ms = 1e3 * clock.seconds();
    if (running) ++flight->run.updates_during;  // the thread never touches this field
    r.relinearized += s.variables_relinearized;
    r.indeterminate += s.indeterminate_cliques;
    r.rows.push_back({static_cast<int>(r.rows.size()) + 1, fed, ms, s.cliques_reeliminated,
                      s.variables_relinearized});
    collect(false, &r.rows.back());
    const int updates = static_cast<int>(r.rows.size());
    if (loop.every > 0 && updates % loop.every == 0 && smoother.smoother().numPoses() > 1) {
      if (flight) {
        ++result.skipped;
      } else {
        flight = std::make_unique<InFlight<G>>();
        flight->snap = smoother.snapshot(&flight->incremental);
        flight->run.update = updates;
        InFlight<G>* f = flight.get();
        const BatchKind kind = loop.kind;
        auto solve = [f, kind] {
          try {
            solveSnapshot(kind, f->snap, f->incremental, &f->batch, &f->run);
          } catch (...) {
            f->error = std::current_exception();
          }
          f->done.store(true);
        };
        if (loop.synchronous) {
          solve();
          collect(true, &r.rows.back());
        } else {
          f->thread = std::thread(solve);
        }
      }
    }
  }
  collect(true, nullptr);  // the batch still in flight at the end of the stream

  r.F_incremental = smoother.smoother().objective();
  Stopwatch finalize_clock;
  if (settings.finalize) {
    const UpdateStats s = smoother.finalize();
    r.relinearized += s.variables_relinearized;
    r.indeterminate += s.indeterminate_cliques;
  }
  r.finalize_s = finalize_clock.seconds();
  r.pending = smoother.pending();
  std::vector<double> ms;
  for (const auto& row : r.rows) ms.push_back(row.latency_ms);
  r.latency = summarizeLatency(ms);
  r.update_s = std::accumulate(ms.begin(), ms.end(), 0.0) / 1e3;
  r.total_s = r.update_s + r.finalize_s;
  r.poses = smoother.graphEstimate();
  r.F_final = objective(graph, r.poses);

  if (loop.final_run && smoother.smoother().numPoses() > 1) {
    std::vector<G> incremental, batch;
    const PoseGraph<G> snap = smoother.snapshot(&incremental);
    BatchRun run;
    run.update = static_cast<int>(r.rows.size());
    run.final_run = true;
    solveSnapshot(loop.kind, snap, incremental, &batch, &run);
    r.batch_poses = smoother.toGraphOrder(batch);
    r.batch.F_initial = run.F_incremental;
    r.batch.F_final = objective(graph, r.batch_poses);
    r.batch.time_s = run.time_s;
    r.batch.iterations = run.iterations;
    r.batch.termination = Termination::kConverged;
    if (loop.reseed && run.winner == "batch") {  // the final estimate is the better one
      r.poses = r.batch_poses;
      r.F_final = r.batch.F_final;
      run.reseeded = true;
      run.reseed_update = run.update;
    }
    result.batches.push_back(run);
  }
  return result;
}

template LoopResult<SE2> runReplayWithBatches(const PoseGraph<SE2>&, const ReplaySettings&,
                                              const BatchLoopSettings&);
template LoopResult<SE3> runReplayWithBatches(const PoseGraph<SE3>&, const ReplaySettings&,
                                              const BatchLoopSettings&);

}  // namespace arbor::cli
