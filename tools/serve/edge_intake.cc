#include "arbor_slam/tools/serve/edge_intake.h"

#include <algorithm>
#include <limits>
#include <stdexcept>

#include "arbor_slam/io/lcm_messages.h"

namespace arbor::serve {
namespace {

/// total += n (n >= 0), stopping at INT64_MAX: a seq near 2^63 cannot overflow a gap count.
void addSaturating(std::int64_t& total, std::int64_t n) {
  constexpr std::int64_t kMax = std::numeric_limits<std::int64_t>::max();
  total = n > kMax - total ? kMax : total + n;
}

/// The dimension a held message would fix (0: a command, which has none).
int heldDim(const IntakeResult& r) {
  if (r.is_command) return 0;
  return r.is_prior ? dimOf(r.prior) : (r.edge.index() == 0 ? 2 : 3);
}

}  // namespace

std::uint64_t EdgeIntake::fingerprint(const void* data, int size) {
  std::uint64_t h = 1469598103934665603ULL;
  const auto* p = static_cast<const unsigned char*>(data);
  for (int k = 0; k < size; ++k) h = (h ^ p[k]) * 1099511628211ULL;
  return h ^ static_cast<std::uint64_t>(size);
}

EdgeIntake::EdgeIntake(int dim, std::int64_t window, std::size_t max_senders)
    : dim_(dim),
      window_(window),
      max_senders_(max_senders),
      jump_limit_(std::max<std::int64_t>(1, window - 1)) {
  if (window < 1) {
    throw std::invalid_argument("EdgeIntake: window " + std::to_string(window) + " is not >= 1");
  }
  if (max_senders < 1) throw std::invalid_argument("EdgeIntake: max senders 0 is not >= 1");
}

EdgeIntake::Stream& EdgeIntake::stream(Kind kind) {
  return kind == Kind::kCommand ? commands_ : kind == Kind::kPrior ? priors_ : edges_;
}

std::size_t EdgeIntake::senders(Kind kind) const {
  const Stream& s = kind == Kind::kCommand ? commands_ : kind == Kind::kPrior ? priors_ : edges_;
  return s.senders.size();
}

void EdgeIntake::refuse(Kind kind, const std::string& reason) {
  IntakeCounts& c = stream(kind).counts;
  ++c.received;
  ++c.rejected;
  ++c.rejected_by_reason[reason];
}

std::vector<std::pair<std::int64_t, std::int64_t>> EdgeIntake::gapsBySender(Kind kind) const {
  const Stream& s = kind == Kind::kCommand ? commands_ : kind == Kind::kPrior ? priors_ : edges_;
  std::vector<std::pair<std::int64_t, std::int64_t>> out;
  for (const auto& [sender, table] : s.senders) {
    if (table.gaps > 0) out.emplace_back(sender, table.gaps);
  }
  std::sort(out.begin(), out.end());
  return out;
}

std::vector<std::pair<std::int64_t, std::int64_t>> EdgeIntake::highestBySender(Kind kind) const {
  const Stream& s = kind == Kind::kCommand ? commands_ : kind == Kind::kPrior ? priors_ : edges_;
  std::vector<std::pair<std::int64_t, std::int64_t>> out;
  for (const auto& [sender, table] : s.senders) out.emplace_back(sender, table.highest);
  std::sort(out.begin(), out.end());
  return out;
}

std::size_t EdgeIntake::trackedSeqs(std::int64_t sender) const {
  const auto it = edges_.senders.find(sender);
  return it == edges_.senders.end() ? 0 : it->second.ring.size();
}

std::uint64_t* EdgeIntake::slot(Sender& s, std::int64_t seq, bool grow) const {
  const auto index = static_cast<std::size_t>((seq - 1) % window_);
  if (index >= s.ring.size()) {
    if (!grow) return nullptr;
    if (index >= s.ring.capacity()) {  // geometric growth, never past the window
      s.ring.reserve(static_cast<std::size_t>(
          std::min<std::int64_t>(window_, std::max(index + 1, 2 * s.ring.capacity()))));
    }
    s.ring.resize(index + 1, 0);
  }
  return &s.ring[index];
}

void EdgeIntake::advance(Sender& s, std::int64_t seq) const {
  // The slots of s.highest + 1 .. seq held seq numbers now below the window: forget them.
  if (seq - s.highest >= window_) {
    std::fill(s.ring.begin(), s.ring.end(), 0);
  } else {
    for (std::int64_t q = s.highest + 1; q <= seq; ++q) {
      if (std::uint64_t* e = slot(s, q, false)) *e = 0;
    }
  }
  s.highest = seq;
}

IntakeResult EdgeIntake::reject(Stream& stream, IntakeResult r, const std::string& reason,
                                const std::string& detail) {
  r.verdict = Intake::kRejected;
  r.reason = reason;
  r.detail = detail;
  ++stream.counts.rejected;
  ++stream.counts.rejected_by_reason[reason];
  return r;
}

IntakeResult EdgeIntake::repeated(Stream& stream, IntakeResult r, bool same_contents,
                                  const std::string& where) {
  if (same_contents) {
    r.verdict = Intake::kDuplicate;
    r.reason = "duplicate";
    ++stream.counts.duplicates;
    return r;
  }
  const std::string detail = "seq " + std::to_string(r.seq) + " of sender " +
                             std::to_string(r.sender) + " " + where + " with other contents";
  return reject(stream, std::move(r), "seq reused", detail);
}

void EdgeIntake::revoke(const IntakeResult& accepted, const std::string& reason) {
  if (accepted.verdict != Intake::kAccepted) return;
  Stream& stream = accepted.is_command ? commands_ : accepted.is_prior ? priors_ : edges_;
  bool gap = true;  // its seq is missing now, until it is sent again
  const auto known = stream.senders.find(accepted.sender);
  if (known != stream.senders.end()) {  // else evicted meanwhile: nothing to forget
    Sender& s = known->second;
    if (accepted.seq > s.highest) {  // an edge command beyond the jump limit: not a gap
      const auto it = std::find_if(s.jumped.begin(), s.jumped.end(),
                                   [&](const auto& j) { return j.first == accepted.seq; });
      if (it != s.jumped.end()) s.jumped.erase(it);
      gap = false;
    } else {
      if (accepted.seq > s.highest - window_) {
        if (std::uint64_t* e = slot(s, accepted.seq, false)) *e = 0;
      }
      addSaturating(s.gaps, 1);
    }
  }
  IntakeCounts& c = stream.counts;
  --c.accepted;
  if (gap) addSaturating(c.gaps, 1);
  ++c.rejected;
  ++c.rejected_by_reason[reason];
}

IntakeResult EdgeIntake::admit(const void* data, int size) {
  EdgeDecoding d = decodeEdge(data, size);
  if (!d.ok()) {
    ++edges_.counts.received;
    return reject(edges_, IntakeResult(), toString(d.problem), d.detail);
  }
  return admitEdge(std::move(d.edge), fingerprint(data, size), data, size);
}

IntakeResult EdgeIntake::admitPrior(const void* data, int size) {
  PriorDecoding d = decodePrior(data, size);
  if (!d.ok()) {
    ++priors_.counts.received;
    IntakeResult r;
    r.is_prior = true;
    return reject(priors_, std::move(r), toString(d.problem), d.detail);
  }
  return admitPrior(std::move(d.prior), fingerprint(data, size), data, size);
}

IntakeResult EdgeIntake::admitCommand(const void* data, int size) {
  EdgeCommandDecoding d = decodeEdgeCommand(data, size);
  if (!d.ok()) {
    ++commands_.counts.received;
    IntakeResult r;
    r.is_command = true;
    return reject(commands_, std::move(r), toString(d.problem), d.detail);
  }
  return admitCommand(d.command, fingerprint(data, size), data, size);
}

IntakeResult EdgeIntake::admit(const Arrival& a) {
  if (!a.problem.empty()) {
    Stream& s = stream(a.kind);
    ++s.counts.received;
    IntakeResult r;
    r.is_prior = a.kind == Kind::kPrior;
    r.is_command = a.kind == Kind::kCommand;
    return reject(s, std::move(r), a.problem, a.detail);
  }
  switch (a.kind) {
    case Kind::kPrior:
      return admitPrior(a.prior, a.fingerprint, a.wire, a.wire_size);
    case Kind::kCommand:
      return admitCommand(a.command, a.fingerprint, a.wire, a.wire_size);
    case Kind::kEdge:
      break;
  }
  return admitEdge(a.edge, a.fingerprint, a.wire, a.wire_size);
}

IntakeResult EdgeIntake::admitEdge(AnyStreamEdge edge, std::uint64_t fp, const void* wire,
                                   int wire_size) {
  ++edges_.counts.received;
  IntakeResult r;
  std::visit(
      [&](const auto& e) {
        r.sender = e.sender;
        r.seq = e.seq;
      },
      edge);
  const int dim = edge.index() == 0 ? 2 : 3;
  r.edge = std::move(edge);  // kept while held; dropped below unless accepted
  r = admitSeq(edges_, std::move(r), dim, fp, wire, wire_size);
  if (r.verdict != Intake::kAccepted) r.edge = AnyStreamEdge();
  return r;
}

IntakeResult EdgeIntake::admitPrior(AnyStreamPrior prior, std::uint64_t fp, const void* wire,
                                    int wire_size) {
  ++priors_.counts.received;
  IntakeResult r;
  r.is_prior = true;
  std::visit(
      [&](const auto& p) {
        r.sender = p.sender;
        r.seq = p.seq;
      },
      prior);
  const int dim = dimOf(prior);
  r.prior = std::move(prior);
  r = admitSeq(priors_, std::move(r), dim, fp, wire, wire_size);
  if (r.verdict != Intake::kAccepted) r.prior = AnyStreamPrior();
  return r;
}

IntakeResult EdgeIntake::admitCommand(const StreamEdgeCommand& command, std::uint64_t fp,
                                      const void* wire, int wire_size) {
  ++commands_.counts.received;
  IntakeResult r;
  r.is_command = true;
  r.sender = command.sender;
  r.seq = command.seq;
  r.command = command;
  // A command has no dimension.
  r = admitSeq(commands_, std::move(r), dim_, fp, wire, wire_size);
  if (r.verdict != Intake::kAccepted) r.command = StreamEdgeCommand();
  return r;
}

EdgeIntake::Sender& EdgeIntake::table(Stream& stream, IntakeResult& r) {
  auto known = stream.senders.find(r.sender);
  if (known == stream.senders.end()) {
    if (stream.senders.size() >= max_senders_) {
      // The least recently heard sender's table goes: O(max_senders) once per new sender.
      auto idle = stream.senders.begin();
      for (auto it = stream.senders.begin(); it != stream.senders.end(); ++it) {
        if (it->second.heard < idle->second.heard) idle = it;
      }
      r.evicted = idle->first;
      r.dropped += dropHeld(stream, idle->second);
      stream.senders.erase(idle);
      ++stream.counts.senders_evicted;
    }
    known = stream.senders.emplace(r.sender, Sender()).first;
  }
  known->second.heard = ++heard_;
  return known->second;
}

std::int64_t EdgeIntake::dropHeld(Stream& stream, Sender& s) {
  const auto n = static_cast<std::int64_t>(s.held.size());
  if (n == 0) return 0;
  stream.counts.held -= n;
  stream.counts.rejected += n;
  stream.counts.rejected_by_reason["unconfirmed jump"] += n;
  s.held.clear();
  s.jump_from = 0;
  return n;
}

IntakeResult EdgeIntake::acceptJumpedCommand(Stream& stream, Sender& s, IntakeResult r,
                                             std::uint64_t fp) {
  for (const auto& [seq, seen] : s.jumped)
    if (seq == r.seq) return repeated(stream, std::move(r), seen == fp, "was already received");
  if (s.jumped.size() >= kRecentJumps) s.jumped.erase(s.jumped.begin());
  s.jumped.emplace_back(r.seq, fp);
  r.verdict = Intake::kAccepted;
  ++stream.counts.accepted;
  return r;
}

IntakeResult EdgeIntake::holdJump(Stream& stream, Sender& s, IntakeResult r, std::uint64_t fp,
                                  const void* wire, int wire_size) {
  // One run, of one dimension (which matters while the stream's is not fixed yet).
  const bool in_run = !s.held.empty() && r.seq >= s.jump_from &&
                      r.seq - s.jump_from < kConfirmRun && heldDim(s.held[0]) == heldDim(r);
  if (in_run) {
    for (const IntakeResult& h : s.held)
      if (h.seq == r.seq) return repeated(stream, std::move(r), h.fingerprint == fp, "is held");
  } else {
    r.dropped += dropHeld(stream, s);  // a jump elsewhere: what was held is not confirmed
    s.jump_from = r.seq;
  }
  r.fingerprint = fp;
  if (static_cast<int>(s.held.size()) + 1 < kConfirmRun) {
    IntakeResult held = r;
    held.verdict = Intake::kAccepted;  // as it will be when released
    held.dropped = 0;
    held.evicted = 0;
    if (wire != nullptr && wire_size > 0) {
      const auto* bytes = static_cast<const unsigned char*>(wire);
      held.wire.assign(bytes, bytes + wire_size);
    }
    s.held.push_back(std::move(held));
    ++stream.counts.held;
    r.verdict = Intake::kHeld;
    r.reason = "held";
    r.detail = "seq " + std::to_string(r.seq) + " of sender " + std::to_string(r.sender) +
               " is more than " + std::to_string(jump_limit_) + " above its highest seq " +
               std::to_string(s.highest) + ": held until seqs " + std::to_string(s.jump_from) +
               " to " + std::to_string(s.jump_from + (kConfirmRun - 1)) + " confirm the jump";
    return r;
  }
  // Confirmed: the run s.jump_from .. s.jump_from + kConfirmRun − 1 is complete.
  const std::int64_t last = s.jump_from + (kConfirmRun - 1);
  r.skipped = s.jump_from - s.highest - 1;
  addSaturating(stream.counts.gaps, r.skipped);
  addSaturating(s.gaps, r.skipped);
  advance(s, last);
  *slot(s, r.seq, true) = fp;
  for (IntakeResult& h : s.held) *slot(s, h.seq, true) = h.fingerprint;
  r.released = std::move(s.held);
  s.held.clear();
  s.jump_from = 0;
  const auto n = static_cast<std::int64_t>(r.released.size());
  stream.counts.held -= n;
  stream.counts.accepted += n + 1;
  ++stream.counts.jumps_confirmed;
  if (dim_ == 0 && !r.is_command) dim_ = heldDim(r);
  r.verdict = Intake::kAccepted;
  return r;
}

IntakeResult EdgeIntake::admitSeq(Stream& stream, IntakeResult r, int dim, std::uint64_t contents,
                                  const void* wire, int wire_size) {
  const char* what = r.is_command ? "edge command" : r.is_prior ? "prior" : "edge";
  if (dim_ != 0 && dim != dim_) {
    return reject(
        stream, std::move(r), "dim",
        "a " + std::to_string(dim) + "D " + what + " on a " + std::to_string(dim_) + "D stream");
  }
  Sender& s = table(stream, r);
  const std::uint64_t fp = std::max<std::uint64_t>(contents, 1);  // 0: empty slot
  r.fingerprint = fp;
  // seq >= 1 and highest >= 0: no overflow.
  if (r.seq - s.highest > jump_limit_) {
    if (r.is_command) return acceptJumpedCommand(stream, s, std::move(r), fp);
    return holdJump(stream, s, std::move(r), fp, wire, wire_size);
  }
  if (r.seq <= s.highest - window_) {
    return reject(stream, std::move(r), "stale",
                  "seq " + std::to_string(r.seq) + " of sender " + std::to_string(r.sender) +
                      " is " + std::to_string(window_) + " or more below its highest seq " +
                      std::to_string(s.highest) + ": too old to tell a late " + what +
                      " from a repeat");
  }
  if (r.seq <= s.highest) {
    const std::uint64_t* seen = slot(s, r.seq, false);
    if (seen != nullptr && (*seen == fp || *seen != 0))
      return repeated(stream, std::move(r), *seen == fp, "was already received");
    // A late message fills a gap reported before (a saturated count stays an upper bound).
    if (stream.counts.gaps > 0) --stream.counts.gaps;
    if (s.gaps > 0) --s.gaps;
  } else {
    r.skipped = r.seq - s.highest - 1;
    addSaturating(stream.counts.gaps, r.skipped);
    addSaturating(s.gaps, r.skipped);
    advance(s, r.seq);
  }
  *slot(s, r.seq, true) = fp;
  // The sender speaks inside its window: a jump held meanwhile was not its own.
  r.dropped += dropHeld(stream, s);
  if (dim_ == 0) dim_ = dim;
  r.verdict = Intake::kAccepted;
  ++stream.counts.accepted;
  return r;
}

}  // namespace arbor::serve
