#include "arbor_slam/tools/serve/serve_engine.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <map>
#include <stdexcept>
#include <vector>

#include "arbor_slam/io/pose_graph_file.h"
#include "arbor_slam/io/trajectory_writer.h"

namespace arbor::serve {
namespace {

template <class G>
class EngineImpl final : public Engine {
 public:
  EngineImpl(const SmootherOptions& options, const refine::RefinerOptions& batch,
             const std::optional<RobustOptions>& robust)
      : smoother_(makeOptions(options, robust)), refiner_(batch) {}

  int dim() const override { return G::kDim; }

  EdgeResult add(const AnyStreamEdge& any) override {
    const auto* e = std::get_if<StreamEdge<G>>(&any);
    if (e == nullptr) {
      return {EdgeStatus::kRejected, "edge of another dimension than the stream"};
    }
    const size_t known = smoother_.ids().size();
    const EdgeResult r = smoother_.addEdge(e->from, e->to, e->z, e->omega, e->trust, e->kernel);
    stampNewPoses(known, e->utime);
    return r;
  }

  EdgeResult addPrior(const AnyStreamPrior& any) override {
    const size_t known = smoother_.ids().size();
    EdgeResult r{EdgeStatus::kRejected, "prior of another dimension than the stream"};
    if (const auto* p = std::get_if<StreamPosePrior<G>>(&any)) {
      r = smoother_.addPosePrior(p->id, p->z, p->omega, p->offset);
      stampNewPoses(known, p->utime);
    } else if (const auto* p = std::get_if<StreamPositionPrior<G>>(&any)) {
      r = smoother_.addPositionPrior(p->id, p->p, p->omega);
      stampNewPoses(known, p->utime);
    }
    return r;
  }

  EdgeSwitchResult command(const StreamEdgeCommand& c) override {
    return c.kind == StreamEdgeCommand::Kind::kDisable ? smoother_.disableEdge(c.from, c.to)
                                                       : smoother_.enableEdge(c.from, c.to);
  }

  // The poses an update may have changed (IncrementalSmoother::updatedPoses) wait for the next
  // "changed" message. The engine's OnlineSmoother runs one smoother update per update() (no
  // robust layer, whose graduation would run several), so the last update's list is complete.
  UpdateStats update() override {
    const UpdateStats st = smoother_.update();
    noteChanged(smoother_.smoother().updatedPoses());
    return st;
  }
  int cliquesDeferred() const override { return smoother_.smoother().cliquesDeferred(); }
  void solveDeferred(double budget_mb) override {
    if (smoother_.smoother().cliquesDeferred() == 0) return;  // updatedPoses() is the update's
    smoother_.solveDeferred(budget_mb);
    noteChanged(smoother_.smoother().updatedPoses());
  }
  UpdateStats refine(const CancellationToken* cancel) override {
    const UpdateStats st = smoother_.finalize(cancel);
    noteChanged(smoother_.smoother().updatedPoses());
    return st;
  }
  double objective() const override { return smoother_.objective(); }
  OnlineStats stats() const override { return smoother_.stats(); }
  std::vector<ClosureReport> closures() const override { return smoother_.closures(); }
  double inlierThreshold() const override {
    return smoother_.gnc() ? smoother_.gnc()->threshold() : 0.0;
  }

  Estimate estimate(bool full) override {
    Estimate m = full ? message(smoother_.smoother().estimate(), true) : changedMessage();
    m.F = full ? objective() : std::numeric_limits<double>::quiet_NaN();
    return m;
  }

  Eigen::MatrixXd covariance(const std::vector<Key>& ids) const override {
    if (ids.size() == 1) return smoother_.marginalCovariance(ids[0]);
    if (ids.size() == 2) return smoother_.jointMarginalCovariance(ids[0], ids[1]);
    throw std::invalid_argument("covariance of " + std::to_string(ids.size()) + " poses (1 or 2)");
  }

  const refine::RefinerOptions& batchOptions() const override { return refiner_.options(); }
  bool startBatch(std::int64_t update) override { return refiner_.start(smoother_, update); }
  void noteUpdate() override { refiner_.noteUpdate(); }
  bool batchInFlight() const override { return refiner_.inFlight(); }
  int batchesSkipped() const override { return refiner_.skipped(); }

  std::optional<refine::BatchRun> collectBatch(bool wait, Estimate* seed) override {
    seed->num_poses = 0;
    std::optional<refine::BatchOutcome<G>> done = refiner_.collect(wait);
    if (!done) return std::nullopt;
    if (refiner_.options().reseed && !done->best.empty()) {
      const std::vector<G> point = smoother_.seedPoint(refine::seedValues(smoother_, *done));
      const auto keep = published_;  // a seed message is not a published estimate
      *seed = message(point, true);
      published_ = keep;
      seed->F = std::numeric_limits<double>::quiet_NaN();
    }
    return done->run;
  }

  ReseedResult reseed(const Estimate& seed) override {
    if (seed.dim != G::kDim) {
      throw std::invalid_argument("reseed: a " + std::to_string(seed.dim) + "D estimate for a " +
                                  std::to_string(G::kDim) + "D stream");
    }
    const size_t n = static_cast<size_t>(std::max(0, seed.num_poses));
    if (seed.ids.size() != n || seed.translation.size() != n || seed.rotation.size() != n) {
      throw std::invalid_argument("reseed: num_poses " + std::to_string(seed.num_poses) +
                                  " does not match the arrays");
    }
    std::map<Key, G> values;
    for (size_t k = 0; k < n; ++k) {
      values[seed.ids[k]] = poseFromFields<G>(seed.translation[k].data(), seed.rotation[k].data());
    }
    const ReseedResult result = smoother_.reseed(values, /*only_if_lower=*/true);
    for (int k = 0; k < smoother_.smoother().numPoses(); ++k) noteChanged(k);  // rebuilt
    return result;
  }

 private:
  /// poses (dense order) as a message: all (`full`) or those whose fields changed since the
  /// last message; remembers what it put in.
  Estimate message(const std::vector<G>& poses, bool full) {
    const std::vector<Key>& ids = smoother_.ids();
    Estimate m;
    m.dim = G::kDim;
    m.full = full;
    m.total_poses = static_cast<int32_t>(poses.size());
    published_.resize(poses.size());
    for (size_t k = 0; k < poses.size(); ++k) {
      Fields f;
      poseToFields(poses[k], f.data(), f.data() + 3);
      if (!full && f == published_[k]) continue;
      published_[k] = f;
      m.ids.push_back(ids[k]);
      m.translation.emplace_back(f.begin(), f.begin() + 3);
      m.rotation.emplace_back(f.begin() + 3, f.end());
    }
    m.num_poses = static_cast<int32_t>(m.ids.size());
    return m;
  }

  void noteChanged(int k) {
    if (static_cast<size_t>(k) >= is_changed_.size()) is_changed_.resize(k + 1, 0);
    if (is_changed_[k]) return;
    is_changed_[k] = 1;
    changed_.push_back(k);
  }
  void noteChanged(const std::vector<int>& poses) {
    for (int k : poses) noteChanged(k);
  }

  /// The "changed" message: the poses new since the last message (fixed ones included) and, of
  /// those updates may have changed since, the ones whose fields differ from what was published
  /// (dense order). O(poses listed), not O(all poses).
  Estimate changedMessage() {
    const IncrementalSmoother<G>& s = smoother_.smoother();
    const std::vector<Key>& ids = smoother_.ids();
    const int n = s.numPoses();
    const int first_new = static_cast<int>(published_.size());  // never published: always sent
    for (int k = first_new; k < n; ++k) noteChanged(k);
    published_.resize(static_cast<size_t>(n));
    std::sort(changed_.begin(), changed_.end());
    Estimate m;
    m.dim = G::kDim;
    m.full = false;
    m.total_poses = n;
    for (int k : changed_) {
      is_changed_[k] = 0;
      if (k >= n) continue;
      Fields f;
      poseToFields(s.estimate(k), f.data(), f.data() + 3);
      if (k < first_new && f == published_[k]) continue;
      published_[k] = f;
      m.ids.push_back(ids[k]);
      m.translation.emplace_back(f.begin(), f.begin() + 3);
      m.rotation.emplace_back(f.begin() + 3, f.end());
    }
    changed_.clear();
    m.num_poses = static_cast<int32_t>(m.ids.size());
    return m;
  }

 public:
  void writeG2o(const std::string& path) const override {
    const PoseGraph<G> graph = graphOfEstimate();
    writeG2oFile(path, graph, graph.poses);
  }

  void writeEstimate(const std::string& path, TrajectoryFormat format) const override {
    const PoseGraph<G> graph = graphOfEstimate();
    writeEstimateFile(path, format, graph, graph.poses, &stamps_);
  }

 private:
  // The poses the smoother created since it knew `known` are stamped `utime` (µs) in seconds.
  void stampNewPoses(size_t known, std::int64_t utime) {
    const std::vector<Key>& ids = smoother_.ids();
    for (size_t k = known; k < ids.size(); ++k) stamps_.emplace(ids[k], 1e-6 * double(utime));
  }

  // The estimate and the edges applied but the disabled ones, poses by ascending id.
  PoseGraph<G> graphOfEstimate() const {
    const std::vector<G> poses = smoother_.smoother().estimate();
    const std::vector<Key>& ids = smoother_.ids();
    PoseGraph<G> graph;
    std::vector<int> order(ids.size());
    for (size_t k = 0; k < ids.size(); ++k) order[k] = static_cast<int>(k);
    std::sort(order.begin(), order.end(), [&](int a, int b) { return ids[a] < ids[b]; });
    std::vector<int> dense_to_graph(ids.size());
    for (int g = 0; g < static_cast<int>(order.size()); ++g) {
      dense_to_graph[order[g]] = g;
      graph.ids.push_back(ids[order[g]]);
      graph.index[ids[order[g]]] = g;
      graph.poses.push_back(poses[order[g]]);
    }
    const auto& factors = smoother_.smoother().factors();
    for (int index = 0; index < static_cast<int>(factors.size()); ++index) {
      if (smoother_.factorDisabled(index)) continue;
      Factor<G> f = factors[index];
      f.setKeys(dense_to_graph[f.key(0)], f.arity() > 1 ? dense_to_graph[f.key(1)] : -1);
      addToGraph(f, &graph);
    }
    for (int k = 0; k < static_cast<int>(ids.size()); ++k) {
      if (smoother_.smoother().isFixed(k)) graph.fixed.push_back(dense_to_graph[k]);
    }
    std::sort(graph.fixed.begin(), graph.fixed.end());
    graph.has_initial_estimate = true;
    return graph;
  }

  using Fields = std::array<double, 7>;
  static OnlineSmootherOptions<G> makeOptions(const SmootherOptions& s,
                                              const std::optional<RobustOptions>& robust) {
    OnlineSmootherOptions<G> o;
    o.smoother = s;
    o.robust = robust;
    return o;
  }
  OnlineSmoother<G> smoother_;
  refine::BatchRefiner<G> refiner_;
  std::vector<Fields> published_;  ///< per dense index: the values last put in a message
  std::vector<int> changed_;       ///< poses to compare at the next "changed" message
  std::vector<char> is_changed_;   ///< per dense index: listed in changed_
  PoseStamps stamps_;  ///< per pose id: the utime of the edge or prior that created it, in s
};

}  // namespace

std::unique_ptr<Engine> makeEngine(int dim, const SmootherOptions& options,
                                   const refine::RefinerOptions& batch,
                                   const std::optional<RobustOptions>& robust) {
  if (dim == 2) return std::make_unique<EngineImpl<SE2>>(options, batch, robust);
  if (dim == 3) return std::make_unique<EngineImpl<SE3>>(options, batch, robust);
  throw std::invalid_argument("makeEngine: dim " + std::to_string(dim) + " is not 2 or 3");
}

}  // namespace arbor::serve
