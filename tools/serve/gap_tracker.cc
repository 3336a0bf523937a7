#include "arbor_slam/tools/serve/gap_tracker.h"

#include <algorithm>
#include <limits>
#include <stdexcept>
#include <string>

#include "arbor_slam/io/lcm_messages.h"

namespace arbor::serve {
namespace {

/// total += n (n >= 0), stopping at INT64_MAX.
void addSaturating(std::int64_t& total, std::int64_t n) {
  constexpr std::int64_t kMax = std::numeric_limits<std::int64_t>::max();
  total = n > kMax - total ? kMax : total + n;
}

MeasurementKind kindOf(const IntakeResult& r) {
  return r.is_prior ? MeasurementKind::kPrior : MeasurementKind::kEdge;
}

}  // namespace

GapTracker::GapTracker(Clock::duration hold, std::size_t limit, std::int64_t window)
    : hold_(hold), limit_(limit), window_(window) {
  if (limit < 1) throw std::invalid_argument("GapTracker: limit 0 is not >= 1");
  if (window < 1) {
    throw std::invalid_argument("GapTracker: window " + std::to_string(window) + " is not >= 1");
  }
}

void GapTracker::drain(Sender& s, std::vector<IntakeResult>& out) {
  for (auto it = s.held.begin(); it != s.held.end() && it->first == s.next; it = s.held.erase(it)) {
    out.push_back(std::move(it->second.r));
    ++counts_.reordered;
    --counts_.held;
    ++s.next;
  }
}

void GapTracker::giveUpHead(Sender& s, std::int64_t to, std::vector<IntakeResult>& out,
                            std::int64_t* given_up) {
  if (to < s.next) return;
  std::int64_t lost = 0, runs = 0, cursor = s.next;
  for (auto it = s.held.begin(); it != s.held.end() && it->first <= to; it = s.held.erase(it)) {
    if (it->first > cursor) {
      addSaturating(lost, it->first - cursor);
      ++runs;
    }
    out.push_back(std::move(it->second.r));
    ++counts_.reordered;
    --counts_.held;
    cursor = it->first + 1;
  }
  if (to >= cursor) {
    addSaturating(lost, to - cursor + 1);
    ++runs;
  }
  s.next = to + 1;
  addSaturating(counts_.given_up, lost);
  counts_.gaps_given_up += runs;
  if (given_up != nullptr) addSaturating(*given_up, lost);
  drain(s, out);
}

std::vector<IntakeResult> GapTracker::offer(IntakeResult r, Clock::time_point now,
                                            std::int64_t* given_up) {
  std::vector<IntakeResult> out;
  if (!on()) {
    out.push_back(std::move(r));
    return out;
  }
  Sender& s = senders_[idOf(kindOf(r), r.sender)];
  s.heard = true;
  s.last_heard = now;
  s.highest = std::max(s.highest, r.seq);
  if (r.seq < s.next) {  // its gap was given up (or predates a restart): at once
    ++counts_.late;
    out.push_back(std::move(r));
    return out;
  }
  // What lies a window or more below this seq is stale at the intake: never worth asking for.
  if (r.seq - s.next >= window_) giveUpHead(s, r.seq - window_, out, given_up);
  if (r.seq == s.next) {
    ++s.next;
    out.push_back(std::move(r));
    drain(s, out);
    return out;
  }
  const std::int64_t seq = r.seq;
  s.held.emplace(seq, Held{std::move(r), now, s.clock});
  ++counts_.held;
  if (s.held.size() > limit_) giveUpHead(s, s.held.begin()->first - 1, out, given_up);
  return out;
}

void GapTracker::heard(MeasurementKind kind, std::int64_t sender, Clock::time_point now) {
  const auto it = senders_.find(idOf(kind, sender));
  if (it == senders_.end()) return;
  it->second.heard = true;
  it->second.last_heard = now;
}

std::vector<IntakeResult> GapTracker::expire(Clock::time_point now, std::int64_t* given_up) {
  std::vector<IntakeResult> out;
  // The senders' clocks advance while they are heard from (one tick at most a second).
  const Clock::duration dt =
      ticked_ ? std::clamp<Clock::duration>(now - last_tick_, Clock::duration::zero(),
                                            std::chrono::seconds(1))
              : Clock::duration::zero();
  last_tick_ = now;
  ticked_ = true;
  for (auto& [id, s] : senders_) {
    if (now - s.last_heard <= kQuiet) s.clock += dt;
    while (!s.held.empty()) {
      Clock::time_point first = now;
      Clock::duration from = s.clock;
      for (const auto& [seq, h] : s.held) {
        first = std::min(first, h.arrived);
        from = std::min(from, h.waited_from);
      }
      if (s.clock - from < hold_ && now - first < kSilentFactor * hold_) break;
      giveUpHead(s, s.held.begin()->first - 1, out, given_up);
    }
  }
  return out;
}

std::vector<IntakeResult> GapTracker::giveUpTo(MeasurementKind kind, std::int64_t sender,
                                               std::int64_t settled, std::int64_t* given_up) {
  std::vector<IntakeResult> out;
  const auto it = senders_.find(idOf(kind, sender));
  if (it == senders_.end()) return out;
  Sender& s = it->second;
  // Beyond the highest accepted nothing is known missing yet (it may be in flight).
  giveUpHead(s, std::min(settled, s.highest), out, given_up);
  return out;
}

std::vector<IntakeResult> GapTracker::releaseAll(std::int64_t* given_up) {
  std::vector<IntakeResult> out;
  for (auto& [id, s] : senders_) {
    if (!s.held.empty()) giveUpHead(s, s.held.rbegin()->first, out, given_up);
  }
  return out;
}

std::vector<IntakeResult> GapTracker::forget(MeasurementKind kind, std::int64_t sender) {
  std::vector<IntakeResult> out;
  const auto it = senders_.find(idOf(kind, sender));
  if (it == senders_.end()) return out;
  for (auto& [seq, h] : it->second.held) {
    out.push_back(std::move(h.r));
    --counts_.held;
  }
  senders_.erase(it);
  return out;
}

void GapTracker::restore(MeasurementKind kind, std::int64_t sender, std::int64_t highest) {
  if (!on()) return;
  Sender& s = senders_[idOf(kind, sender)];
  s.next = std::max(s.next, highest + 1);
  s.highest = std::max(s.highest, highest);
}

std::int64_t GapTracker::settled(MeasurementKind kind, std::int64_t sender) const {
  const auto it = senders_.find(idOf(kind, sender));
  return it == senders_.end() ? 0 : it->second.next - 1;
}

std::vector<ResendRequest> GapTracker::requests() {
  std::vector<ResendRequest> out;
  if (!on()) return out;
  for (auto& [id, s] : senders_) {
    if (s.held.empty() && !s.heard) continue;
    s.heard = false;
    ResendRequest q;
    q.kind = static_cast<MeasurementKind>(id.first);
    q.sender = id.second;
    q.settled = s.next - 1;
    q.highest = std::max(s.highest, q.settled);
    std::int64_t cursor = s.next;
    for (const auto& [seq, h] : s.held) {
      if (q.missing.size() >= static_cast<std::size_t>(kMaxResendRanges)) break;
      if (seq > cursor) q.missing.emplace_back(cursor, seq - 1);
      cursor = seq + 1;
    }
    ++counts_.requests;
    out.push_back(std::move(q));
  }
  return out;
}

}  // namespace arbor::serve
