#include "arbor/bayestree/online_smoother.h"

#include <chrono>
#include <cmath>
#include <stdexcept>

#include "arbor/core/information.h"
#include "arbor/core/rigid_alignment.h"

namespace arbor {
namespace {

bool finitePose(const SE2& x) {
  return std::isfinite(x.x()) && std::isfinite(x.y()) && std::isfinite(x.cos()) &&
         std::isfinite(x.sin());
}
bool finitePose(const SE3& x) {
  return x.translation().allFinite() && x.quaternion().coeffs().allFinite();
}

}  // namespace

const char* toString(EdgeStatus status) {
  switch (status) {
    case EdgeStatus::kAccepted:
      return "accepted";
    case EdgeStatus::kDuplicate:
      return "duplicate";
    case EdgeStatus::kPending:
      return "pending";
    case EdgeStatus::kRejected:
      return "rejected";
  }
  return "unknown";
}

template <class G>
OnlineSmoother<G>::OnlineSmoother(OnlineSmootherOptions<G> options)
    : options_(options), smoother_(options.smoother) {
  if (!finitePose(options_.gauge))
    throw std::invalid_argument("OnlineSmoother: gauge pose not finite");
}

template <class G>
bool OnlineSmoother<G>::sameMeasurement(const Measurement& a, const Measurement& b) const {
  const double tol = 1e-12;
  if (a.z.localCoordinates(b.z).cwiseAbs().maxCoeff() > tol) return false;
  const double scale = std::max(1.0, a.omega.cwiseAbs().maxCoeff());
  return (a.omega - b.omega).cwiseAbs().maxCoeff() <= tol * scale;
}

template <class G>
int OnlineSmoother<G>::createPose(Key id, const G& value, int creator, bool anchor) {
  const int index =
      creator < 0 && anchor ? smoother_.addFixedPose(value) : smoother_.addPose(value);
  index_.emplace(id, index);
  ids_.push_back(id);
  creator_.push_back(creator);
  component_parent_.push_back(creator < 0 ? index : root(creator));
  components_.emplace_back();
  if (creator < 0) {
    Component& c = components_[index];
    c.members = {index};
    c.first = index;
    c.anchor = anchor ? index : -1;
    ++stats_.components;
  } else {
    components_[root(creator)].members.push_back(index);
  }
  ++stats_.poses;
  return index;
}

template <class G>
int OnlineSmoother<G>::root(int v) const {
  while (component_parent_[v] != v)
    v = component_parent_[v] = component_parent_[component_parent_[v]];
  return v;
}

template <class G>
G OnlineSmoother<G>::moveOntoPriors(const Component& c) const {
  if (c.pose_prior_pose >= 0)
    return c.pose_prior_target.compose(smoother_.estimate(c.pose_prior_pose).inverse());
  std::vector<typename G::Translation> estimated;
  for (int v : c.position_prior_poses) estimated.push_back(smoother_.estimate(v).translation());
  return rigidAlignment<G>(estimated, c.position_prior_values, c.position_prior_weights);
}

// When priors come to fix a component's gauge, the component first moves rigidly into their
// frame (a pose prior's pose onto its value, or the weighted Kabsch fit of its estimated
// positions onto the position priors), so that the first update without the anchor starts near
// the priors instead of wherever the anchor held it; then the anchor is released.
template <class G>
void OnlineSmoother<G>::releaseAnchorIfFixed(int c) {
  Component& comp = components_[c];
  if (comp.anchor < 0 || !comp.gauge.fixesGauge()) return;
  smoother_.transformPoses(comp.members, moveOntoPriors(comp));
  smoother_.releaseFixedPose(comp.anchor);
  comp.anchor = -1;
  ++stats_.anchors_released;
}

// Joining two components by the edge from → to with measurement z. The one that keeps its frame
// ("keep"): the one whose priors fix its gauge, else the older. The other ("move"), unless its
// priors fix its gauge too, moves rigidly so that the edge holds exactly at the current
// estimates: T = x_from z x_to⁻¹ (moving to's side) or x_to z⁻¹ x_from⁻¹ (moving from's side).
// Its anchor is released: the joined component keeps one.
template <class G>
void OnlineSmoother<G>::join(int from, int to, const G& z) {
  const int a = root(from), b = root(to);
  const bool world_a = components_[a].gauge.fixesGauge(),
             world_b = components_[b].gauge.fixesGauge();
  const bool keep_a = world_a != world_b ? world_a : components_[a].first < components_[b].first;
  const int keep = keep_a ? a : b, move = keep_a ? b : a;
  if (!components_[move].gauge.fixesGauge()) {
    const G T = keep_a
                    ? smoother_.estimate(from).compose(z).compose(smoother_.estimate(to).inverse())
                    : smoother_.estimate(to)
                          .compose(z.inverse())
                          .compose(smoother_.estimate(from).inverse());
    smoother_.transformPoses(components_[move].members, T);
  }
  if (components_[move].anchor >= 0) {
    smoother_.releaseFixedPose(components_[move].anchor);
    ++stats_.anchors_released;
  }
  // Union: the members of the smaller list go to the larger one's (O(n log n) over all joins).
  Component moved = std::move(components_[move]);
  components_[move] = Component{};
  Component& kept = components_[keep];
  if (kept.members.size() < moved.members.size()) kept.members.swap(moved.members);
  kept.members.insert(kept.members.end(), moved.members.begin(), moved.members.end());
  kept.gauge.add(moved.gauge);
  if (kept.pose_prior_pose < 0) {
    kept.pose_prior_pose = moved.pose_prior_pose;
    kept.pose_prior_target = moved.pose_prior_target;
  }
  kept.position_prior_poses.insert(kept.position_prior_poses.end(),
                                   moved.position_prior_poses.begin(),
                                   moved.position_prior_poses.end());
  kept.position_prior_values.insert(kept.position_prior_values.end(),
                                    moved.position_prior_values.begin(),
                                    moved.position_prior_values.end());
  kept.position_prior_weights.insert(kept.position_prior_weights.end(),
                                     moved.position_prior_weights.begin(),
                                     moved.position_prior_weights.end());
  kept.first = std::min(kept.first, moved.first);
  component_parent_[move] = keep;
  --stats_.components;
  ++stats_.joins;
  releaseAnchorIfFixed(keep);
}

template <class G>
void OnlineSmoother<G>::apply(const Measurement& m) {
  auto from = index_.find(m.from);
  auto to = index_.find(m.to);
  if (from == index_.end() && to == index_.end()) {  // a new component, anchored at `from`
    const int f = createPose(m.from, options_.gauge, -1);
    createPose(m.to, smoother_.estimate(f).compose(m.z), f);
  } else if (to == index_.end()) {
    createPose(m.to, smoother_.estimate(from->second).compose(m.z), from->second);
  } else if (from == index_.end()) {
    createPose(m.from, smoother_.estimate(to->second).compose(m.z.inverse()), to->second);
  } else if (root(from->second) != root(to->second)) {
    join(from->second, to->second, m.z);
  }
  const auto edge = RelativePoseEdge<G>::make(index_.at(m.from), index_.at(m.to), m.z, m.omega);
  smoother_.addFactor(edge);
  queued_.push_back(edge);
  ++stats_.edges_accepted;
}

template <class G>
EdgeResult OnlineSmoother<G>::addEdge(Key from, Key to, const G& z, const Matrix& omega) {
  auto reject = [&](const std::string& why) {
    ++stats_.edges_rejected;
    return EdgeResult{EdgeStatus::kRejected, why};
  };
  if (!finitePose(z) || !omega.allFinite()) return reject("NaN or infinite value");
  if (from == to) return reject("self-loop on pose " + std::to_string(from));
  const std::string problem = informationProblem(omega);
  if (!problem.empty()) return reject("bad information: " + problem);
  const std::string far = translationProblem(z);
  if (!far.empty()) return reject("bad measurement: " + far);

  Measurement m{from, to, z, omega};
  std::vector<Measurement>& same_pair = seen_[{from, to}];
  for (const Measurement& other : same_pair)
    if (sameMeasurement(m, other)) {
      ++stats_.edges_duplicate;
      return EdgeResult{EdgeStatus::kDuplicate, "repeats an earlier edge " + std::to_string(from) +
                                                    " -> " + std::to_string(to)};
    }
  same_pair.push_back(m);
  apply(m);
  return EdgeResult{EdgeStatus::kAccepted, ""};
}

template <class G>
EdgeResult OnlineSmoother<G>::addPrior(Key id, const Factor<G>& prior, const G& start) {
  auto it = index_.find(id);
  const bool fixes = prior.kind() == FactorKind::kPosePrior;
  int v;
  if (it == index_.end()) {  // a new component, anchored unless the prior fixes its gauge
    v = createPose(id, start, -1, /*anchor=*/!fixes);
  } else {
    v = it->second;
  }
  Factor<G> f = prior;
  f.setKeys(v);
  smoother_.addFactor(f);
  queued_.push_back(f);
  Component& c = components_[root(v)];
  if (const auto* p = f.positionPrior()) {
    c.gauge.addPositionPrior(p->position, p->information);
    c.position_prior_poses.push_back(v);
    c.position_prior_values.push_back(p->position);
    c.position_prior_weights.push_back(G::kDim / p->information.inverse().trace());
  } else {
    c.gauge.addPosePrior();
    if (c.pose_prior_pose < 0) {
      c.pose_prior_pose = v;
      c.pose_prior_target = start;
    }
  }
  // A component still held by its anchor moves onto its priors as far as they say (a
  // translation for one position, a rotation too for more), so that the anchor and the priors
  // do not pull the estimate far apart while the gauge is not yet fixed.
  if (c.anchor >= 0) smoother_.transformPoses(c.members, moveOntoPriors(c));
  releaseAnchorIfFixed(root(v));
  ++stats_.priors_accepted;
  return EdgeResult{EdgeStatus::kAccepted, ""};
}

template <class G>
EdgeResult OnlineSmoother<G>::addPosePrior(Key id, const G& z, const Matrix& omega,
                                           const G& offset) {
  if (!finitePose(z) || !finitePose(offset) || !omega.allFinite()) {
    ++stats_.priors_rejected;
    return {EdgeStatus::kRejected,
            "pose prior on " + std::to_string(id) + ": NaN or infinite value"};
  }
  try {
    const auto prior = PosePriorFactor<G>::make(0, z, omega, offset);
    return addPrior(id, prior, z.compose(offset.inverse()));
  } catch (const std::invalid_argument& e) {
    ++stats_.priors_rejected;
    return {EdgeStatus::kRejected, "pose prior on " + std::to_string(id) + ": " + e.what()};
  }
}

template <class G>
EdgeResult OnlineSmoother<G>::addPositionPrior(Key id, const typename G::Translation& p,
                                               const PositionMatrix& omega) {
  if (!p.allFinite() || !omega.allFinite()) {
    ++stats_.priors_rejected;
    return {EdgeStatus::kRejected,
            "position prior on " + std::to_string(id) + ": NaN or infinite value"};
  }
  try {
    const auto prior = PositionPriorFactor<G>::make(0, p, omega);
    G start;
    if constexpr (G::kDim == 2)
      start = G(p, 0.0);
    else
      start = G(Eigen::Quaterniond::Identity(), p);
    return addPrior(id, prior, start);
  } catch (const std::invalid_argument& e) {
    ++stats_.priors_rejected;
    return {EdgeStatus::kRejected, "position prior on " + std::to_string(id) + ": " + e.what()};
  }
}

template <class G>
int OnlineSmoother<G>::componentOf(Key id) const {
  auto it = index_.find(id);
  if (it == index_.end())
    throw std::out_of_range("OnlineSmoother::componentOf: unknown pose id " + std::to_string(id));
  return root(it->second);
}

template <class G>
std::optional<Key> OnlineSmoother<G>::anchorOf(Key id) const {
  const int a = components_[componentOf(id)].anchor;
  if (a < 0) return std::nullopt;
  return ids_[a];
}

template <class G>
UpdateStats OnlineSmoother<G>::update() {
  return recordUpdate(smoother_.update());
}

template <class G>
UpdateStats OnlineSmoother<G>::finalize() {
  return recordUpdate(smoother_.relinearizeAll());
}

template <class G>
UpdateStats OnlineSmoother<G>::recordUpdate(const UpdateStats& s) {
  queued_.clear();
  poses_at_update_ = static_cast<int>(ids_.size());
  ++stats_.updates;
  stats_.total_update_time_s += s.time_s;
  stats_.last_update = s;
  return s;
}

template <class G>
PoseGraph<G> OnlineSmoother<G>::snapshot() const {
  PoseGraph<G> graph;
  const int n = poses_at_update_;
  graph.ids.assign(ids_.begin(), ids_.begin() + n);
  graph.index.reserve(static_cast<size_t>(n));
  for (int k = 0; k < n; ++k) graph.index.emplace(ids_[k], k);
  graph.poses = smoother_.estimate();
  graph.poses.resize(static_cast<size_t>(n));
  for (const auto& f : smoother_.factors()) addToGraph(f, &graph);  // only poses known then
  for (int k = 0; k < n; ++k)
    if (smoother_.isFixed(k)) graph.fixed.push_back(k);
  graph.has_initial_estimate = true;
  return graph;
}

template <class G>
std::vector<G> OnlineSmoother<G>::completeSeed(std::vector<G> values,
                                               const std::vector<char>& given) const {
  const size_t n = ids_.size();
  const std::vector<G> current = smoother_.estimate();
  // The rigid move that puts the given value of the first pose onto its fixed one (when it is an
  // anchor); every anchor keeps its fixed value.
  const bool first_fixed = smoother_.isFixed(0);
  const G anchor =
      given[0] && first_fixed ? current[0].compose(values[0].inverse()) : G::Identity();
  if (!given[0] || first_fixed) values[0] = current[0];
  for (size_t k = 1; k < n; ++k) {
    if (smoother_.isFixed(static_cast<int>(k))) {
      values[k] = current[k];
    } else if (given[k]) {
      values[k] = anchor.compose(values[k]);
    } else if (creator_[k] < 0) {  // a component's first pose (not fixed: prior-anchored)
      values[k] = current[k];
    } else {  // creators come first in dense order
      const int c = creator_[k];
      values[k] = values[c].compose(current[c].inverse().compose(current[k]));
    }
  }
  return values;
}

template <class G>
std::vector<G> OnlineSmoother<G>::seedPoint(const std::map<Key, G>& values) const {
  std::vector<G> dense(ids_.size());
  std::vector<char> given(ids_.size(), 0);
  for (const auto& [id, value] : values) {
    auto it = index_.find(id);
    if (it == index_.end()) {
      throw std::invalid_argument("OnlineSmoother::reseed: unknown pose id " + std::to_string(id));
    }
    if (!finitePose(value)) {
      throw std::invalid_argument("OnlineSmoother::reseed: the value of pose id " +
                                  std::to_string(id) + " is not finite");
    }
    dense[it->second] = value;
    given[it->second] = 1;
  }
  if (ids_.empty()) return dense;
  return completeSeed(std::move(dense), given);
}

template <class G>
std::vector<G> OnlineSmoother<G>::seedPoint(const std::vector<G>& prefix) const {
  if (prefix.size() > ids_.size()) {
    throw std::invalid_argument("OnlineSmoother::reseed: " + std::to_string(prefix.size()) +
                                " values for " + std::to_string(ids_.size()) + " known poses");
  }
  std::vector<G> dense(ids_.size());
  std::vector<char> given(ids_.size(), 0);
  for (size_t k = 0; k < prefix.size(); ++k) {
    if (!finitePose(prefix[k])) {
      throw std::invalid_argument("OnlineSmoother::reseed: the value of pose id " +
                                  std::to_string(ids_[k]) + " is not finite");
    }
    dense[k] = prefix[k];
    given[k] = 1;
  }
  if (ids_.empty()) return dense;
  return completeSeed(std::move(dense), given);
}

template <class G>
ReseedResult OnlineSmoother<G>::rebuild(const std::vector<G>& seed, bool only_if_lower) {
  ReseedResult result;
  if (ids_.empty()) return result;
  const auto t0 = std::chrono::steady_clock::now();
  IncrementalSmoother<G> fresh(options_.smoother);
  for (size_t k = 0; k < seed.size(); ++k) {
    if (smoother_.isFixed(static_cast<int>(k)))
      fresh.addFixedPose(seed[k]);
    else
      fresh.addPose(seed[k]);
  }
  for (const auto& f : smoother_.factors()) fresh.addFactor(f);
  for (const auto& f : queued_) fresh.addFactor(f);
  result.stats = fresh.update();
  result.F_rebuilt = fresh.objective();
  result.F_before = smoother_.objective();
  if (!queued_.empty()) {  // the queued factors count too, at the current estimate
    const std::vector<G> current = smoother_.estimate();
    for (const auto& f : queued_) result.F_before += f.cost(current);
  }
  result.applied = !only_if_lower || result.F_rebuilt < result.F_before;
  if (result.applied) {
    smoother_ = std::move(fresh);
    queued_.clear();
    poses_at_update_ = static_cast<int>(ids_.size());
  }
  result.stats.time_s =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  if (result.applied) {
    ++stats_.reseeds;
    stats_.total_reseed_time_s += result.stats.time_s;
  }
  return result;
}

template <class G>
ReseedResult OnlineSmoother<G>::reseed(const std::map<Key, G>& values, bool only_if_lower) {
  return rebuild(seedPoint(values), only_if_lower);
}

template <class G>
ReseedResult OnlineSmoother<G>::reseed(const std::vector<G>& prefix, bool only_if_lower) {
  return rebuild(seedPoint(prefix), only_if_lower);
}

template <class G>
bool OnlineSmoother<G>::hasPose(Key id) const {
  return index_.count(id) > 0;
}

template <class G>
G OnlineSmoother<G>::estimate(Key id) const {
  auto it = index_.find(id);
  if (it == index_.end())
    throw std::out_of_range("OnlineSmoother::estimate: unknown pose id " + std::to_string(id));
  return smoother_.estimate(it->second);
}

template <class G>
std::map<Key, G> OnlineSmoother<G>::estimates() const {
  std::map<Key, G> out;
  const std::vector<G> all = smoother_.estimate();
  for (size_t k = 0; k < ids_.size(); ++k) out.emplace(ids_[k], all[k]);
  return out;
}

template <class G>
OnlineStats OnlineSmoother<G>::stats() const {
  return stats_;
}

template class OnlineSmoother<SE2>;
template class OnlineSmoother<SE3>;

}  // namespace arbor
