#include "arbor/tools/serve/edge_intake.h"

#include <algorithm>
#include <stdexcept>

#include "arbor/io/lcm_messages.h"

namespace arbor::serve {

std::uint64_t EdgeIntake::fingerprint(const void* data, int size) {
  std::uint64_t h = 1469598103934665603ULL;
  const auto* p = static_cast<const unsigned char*>(data);
  for (int k = 0; k < size; ++k) h = (h ^ p[k]) * 1099511628211ULL;
  return h ^ static_cast<std::uint64_t>(size);
}

EdgeIntake::EdgeIntake(int dim, std::int64_t window, std::size_t max_senders)
    : dim_(dim), window_(window), max_senders_(max_senders) {
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

void EdgeIntake::revoke(const IntakeResult& accepted, const std::string& reason) {
  if (accepted.verdict != Intake::kAccepted) return;
  Stream& stream = accepted.is_command ? commands_ : accepted.is_prior ? priors_ : edges_;
  Sender& s = stream.senders[accepted.sender];
  if (accepted.seq > s.highest - window_) {
    if (std::uint64_t* e = slot(s, accepted.seq, false)) *e = 0;
  }
  ++s.gaps;
  IntakeCounts& c = stream.counts;
  --c.accepted;
  ++c.gaps;  // its seq is missing now, until it is sent again
  ++c.rejected;
  ++c.rejected_by_reason[reason];
}

IntakeResult EdgeIntake::admit(const void* data, int size) {
  EdgeDecoding d = decodeEdge(data, size);
  if (!d.ok()) {
    ++edges_.counts.received;
    return reject(edges_, IntakeResult(), toString(d.problem), d.detail);
  }
  return admitEdge(std::move(d.edge), fingerprint(data, size));
}

IntakeResult EdgeIntake::admitPrior(const void* data, int size) {
  PriorDecoding d = decodePrior(data, size);
  if (!d.ok()) {
    ++priors_.counts.received;
    IntakeResult r;
    r.is_prior = true;
    return reject(priors_, std::move(r), toString(d.problem), d.detail);
  }
  return admitPrior(std::move(d.prior), fingerprint(data, size));
}

IntakeResult EdgeIntake::admitCommand(const void* data, int size) {
  EdgeCommandDecoding d = decodeEdgeCommand(data, size);
  if (!d.ok()) {
    ++commands_.counts.received;
    IntakeResult r;
    r.is_command = true;
    return reject(commands_, std::move(r), toString(d.problem), d.detail);
  }
  return admitCommand(d.command, fingerprint(data, size));
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
      return admitPrior(a.prior, a.fingerprint);
    case Kind::kCommand:
      return admitCommand(a.command, a.fingerprint);
    case Kind::kEdge:
      break;
  }
  return admitEdge(a.edge, a.fingerprint);
}

IntakeResult EdgeIntake::admitEdge(AnyStreamEdge edge, std::uint64_t fp) {
  ++edges_.counts.received;
  IntakeResult r;
  std::visit(
      [&](const auto& e) {
        r.sender = e.sender;
        r.seq = e.seq;
      },
      edge);
  const int dim = edge.index() == 0 ? 2 : 3;
  r = admitSeq(edges_, std::move(r), dim, fp);
  if (r.verdict == Intake::kAccepted) r.edge = std::move(edge);
  return r;
}

IntakeResult EdgeIntake::admitPrior(AnyStreamPrior prior, std::uint64_t fp) {
  ++priors_.counts.received;
  IntakeResult r;
  r.is_prior = true;
  std::visit(
      [&](const auto& p) {
        r.sender = p.sender;
        r.seq = p.seq;
      },
      prior);
  r = admitSeq(priors_, std::move(r), dimOf(prior), fp);
  if (r.verdict == Intake::kAccepted) r.prior = std::move(prior);
  return r;
}

IntakeResult EdgeIntake::admitCommand(const StreamEdgeCommand& command, std::uint64_t fp) {
  ++commands_.counts.received;
  IntakeResult r;
  r.is_command = true;
  r.sender = command.sender;
  r.seq = command.seq;
  r = admitSeq(commands_, std::move(r), dim_, fp);  // a command has no dimension
  if (r.verdict == Intake::kAccepted) r.command = command;
  return r;
}

IntakeResult EdgeIntake::admitSeq(Stream& stream, IntakeResult r, int dim, std::uint64_t contents) {
  const char* what = r.is_command ? "edge command" : r.is_prior ? "prior" : "edge";
  if (dim_ != 0 && dim != dim_) {
    return reject(
        stream, std::move(r), "dim",
        "a " + std::to_string(dim) + "D " + what + " on a " + std::to_string(dim_) + "D stream");
  }
  auto known = stream.senders.find(r.sender);
  if (known == stream.senders.end()) {
    if (stream.senders.size() >= max_senders_) {
      return reject(stream, std::move(r), "sender limit",
                    "sender " + std::to_string(r.sender) + " would be sender " +
                        std::to_string(max_senders_ + 1) + " of this stream; at most " +
                        std::to_string(max_senders_) + " are tracked (--max-senders)");
    }
    known = stream.senders.emplace(r.sender, Sender()).first;
  }
  Sender& s = known->second;
  const std::uint64_t fp = std::max<std::uint64_t>(contents, 1);  // 0: empty slot
  if (r.seq <= s.highest - window_) {
    return reject(stream, std::move(r), "stale",
                  "seq " + std::to_string(r.seq) + " of sender " + std::to_string(r.sender) +
                      " is " + std::to_string(window_) + " or more below its highest seq " +
                      std::to_string(s.highest) + ": too old to tell a late " + what +
                      " from a repeat");
  }
  if (r.seq <= s.highest) {
    const std::uint64_t* seen = slot(s, r.seq, false);
    if (seen != nullptr && *seen == fp) {
      r.verdict = Intake::kDuplicate;
      r.reason = "duplicate";
      ++stream.counts.duplicates;
      return r;
    }
    if (seen != nullptr && *seen != 0) {
      return reject(stream, std::move(r), "seq reused",
                    "seq " + std::to_string(r.seq) + " of sender " + std::to_string(r.sender) +
                        " was already received with other contents");
    }
    --stream.counts.gaps;  // a late message fills a gap reported before
    --s.gaps;
  } else {
    r.skipped = r.seq - s.highest - 1;
    stream.counts.gaps += r.skipped;
    s.gaps += r.skipped;
    advance(s, r.seq);
  }
  *slot(s, r.seq, true) = fp;
  if (dim_ == 0) dim_ = dim;
  r.verdict = Intake::kAccepted;
  ++stream.counts.accepted;
  return r;
}

}  // namespace arbor::serve
