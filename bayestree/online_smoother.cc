#include "bayestree/online_smoother.h"

#include <chrono>
#include <cmath>
#include <stdexcept>

#include "core/information.h"

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
int OnlineSmoother<G>::createPose(Key id, const G& value, int creator) {
  const int index = ids_.empty() ? smoother_.addFixedPose(value) : smoother_.addPose(value);
  index_.emplace(id, index);
  ids_.push_back(id);
  creator_.push_back(creator);
  ++stats_.poses;
  return index;
}

template <class G>
bool OnlineSmoother<G>::apply(const Measurement& m, Key* created) {
  auto from = index_.find(m.from);
  auto to = index_.find(m.to);
  bool has_created = false;
  if (from != index_.end() && to == index_.end()) {
    createPose(m.to, smoother_.estimate(from->second).compose(m.z), from->second);
    *created = m.to;
    has_created = true;
  } else if (from == index_.end() && to != index_.end()) {
    createPose(m.from, smoother_.estimate(to->second).compose(m.z.inverse()), to->second);
    *created = m.from;
    has_created = true;
  }
  const auto edge = RelativePoseEdge<G>::make(index_.at(m.from), index_.at(m.to), m.z, m.omega);
  smoother_.addFactor(edge);
  queued_.push_back(edge);
  ++stats_.edges_accepted;
  return has_created;
}

template <class G>
void OnlineSmoother<G>::releasePending(Key known) {
  std::vector<Key> work{known};
  while (!work.empty()) {
    const Key k = work.back();
    work.pop_back();
    auto it = pending_by_key_.find(k);
    if (it == pending_by_key_.end()) continue;
    const std::vector<int> list = std::move(it->second);
    pending_by_key_.erase(it);
    for (int p : list) {
      if (!pending_alive_[p]) continue;
      pending_alive_[p] = 0;
      --stats_.edges_pending;
      Key created = 0;
      if (apply(pending_[p], &created)) work.push_back(created);  // iterative, no recursion
    }
  }
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

  if (ids_.empty()) createPose(from, options_.gauge, -1);  // the first pose fixes the gauge
  const bool from_known = index_.count(from) > 0, to_known = index_.count(to) > 0;
  if (!from_known && !to_known) {
    const int p = static_cast<int>(pending_.size());
    pending_.push_back(m);
    pending_alive_.push_back(1);
    pending_by_key_[from].push_back(p);
    pending_by_key_[to].push_back(p);
    ++stats_.edges_pending;
    return EdgeResult{EdgeStatus::kPending, "neither pose is known yet"};
  }
  Key created = 0;
  if (apply(m, &created)) releasePending(created);
  return EdgeResult{EdgeStatus::kAccepted, ""};
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
  graph.edges = smoother_.factors();  // taken in by updates: only poses known at the last one
  if (n > 0) graph.fixed = {0};
  graph.has_initial_estimate = true;
  return graph;
}

template <class G>
std::vector<G> OnlineSmoother<G>::completeSeed(std::vector<G> values,
                                               const std::vector<char>& given) const {
  const size_t n = ids_.size();
  const std::vector<G> current = smoother_.estimate();
  // The rigid move that puts the given gauge value onto the fixed one.
  const G anchor = given[0] ? current[0].compose(values[0].inverse()) : G::Identity();
  values[0] = current[0];  // the gauge keeps its fixed value
  for (size_t k = 1; k < n; ++k) {
    if (given[k]) {
      values[k] = anchor.compose(values[k]);
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
  fresh.addFixedPose(seed[0]);
  for (size_t k = 1; k < seed.size(); ++k) fresh.addPose(seed[k]);
  for (const auto& f : smoother_.factors()) fresh.addFactor(f);
  for (const auto& f : queued_) fresh.addFactor(f);
  result.stats = fresh.update();
  result.F_rebuilt = fresh.objective();
  result.F_before = smoother_.objective();
  if (!queued_.empty()) {  // the queued factors count too, at the current estimate
    const std::vector<G> current = smoother_.estimate();
    for (const auto& f : queued_) result.F_before += f.cost(current[f.i], current[f.j]);
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
