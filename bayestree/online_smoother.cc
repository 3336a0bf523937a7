#include "bayestree/online_smoother.h"

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
int OnlineSmoother<G>::createPose(Key id, const G& value) {
  const int index = ids_.empty() ? smoother_.addFixedPose(value) : smoother_.addPose(value);
  index_.emplace(id, index);
  ids_.push_back(id);
  ++stats_.poses;
  return index;
}

template <class G>
bool OnlineSmoother<G>::apply(const Measurement& m, Key* created) {
  auto from = index_.find(m.from);
  auto to = index_.find(m.to);
  bool has_created = false;
  if (from != index_.end() && to == index_.end()) {
    createPose(m.to, smoother_.estimate(from->second).compose(m.z));
    *created = m.to;
    has_created = true;
  } else if (from == index_.end() && to != index_.end()) {
    createPose(m.from, smoother_.estimate(to->second).compose(m.z.inverse()));
    *created = m.from;
    has_created = true;
  }
  smoother_.addFactor(RelativePoseEdge<G>::make(index_.at(m.from), index_.at(m.to), m.z, m.omega));
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

  Measurement m{from, to, z, omega};
  std::vector<Measurement>& same_pair = seen_[{from, to}];
  for (const Measurement& other : same_pair)
    if (sameMeasurement(m, other)) {
      ++stats_.edges_duplicate;
      return EdgeResult{EdgeStatus::kDuplicate, "repeats an earlier edge " + std::to_string(from) +
                                                    " -> " + std::to_string(to)};
    }
  same_pair.push_back(m);

  if (ids_.empty()) createPose(from, options_.gauge);  // the first pose fixes the gauge
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
  const UpdateStats s = smoother_.update();
  ++stats_.updates;
  stats_.total_update_time_s += s.time_s;
  stats_.last_update = s;
  return s;
}

template <class G>
UpdateStats OnlineSmoother<G>::finalize() {
  const UpdateStats s = smoother_.relinearizeAll();
  ++stats_.updates;
  stats_.total_update_time_s += s.time_s;
  stats_.last_update = s;
  return s;
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
