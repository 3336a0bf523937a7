#include "tools/serve/edge_intake.h"

namespace arbor::serve {
namespace {

// FNV-1a, 64 bit: identifies the exact bytes of a message.
std::uint64_t fingerprint(const void* data, int size) {
  std::uint64_t h = 1469598103934665603ULL;
  const auto* p = static_cast<const unsigned char*>(data);
  for (int k = 0; k < size; ++k) h = (h ^ p[k]) * 1099511628211ULL;
  return h ^ static_cast<std::uint64_t>(size);
}

}  // namespace

IntakeResult EdgeIntake::reject(IntakeResult r, const std::string& reason,
                                const std::string& detail) {
  r.verdict = Intake::kRejected;
  r.reason = reason;
  r.detail = detail;
  ++counts_.rejected;
  ++counts_.rejected_by_reason[reason];
  return r;
}

void EdgeIntake::revoke(const IntakeResult& accepted, const std::string& reason) {
  if (accepted.verdict != Intake::kAccepted) return;
  Sender& s = senders_[accepted.sender];
  s.fingerprints.erase(accepted.seq);
  --counts_.accepted;
  ++counts_.gaps;  // its seq is missing now, until it is sent again
  ++counts_.rejected;
  ++counts_.rejected_by_reason[reason];
}

IntakeResult EdgeIntake::admit(const void* data, int size) {
  ++counts_.received;
  IntakeResult r;
  EdgeDecoding d = decodeEdge(data, size);
  if (!d.ok()) return reject(std::move(r), toString(d.problem), d.detail);
  const int dim = d.edge.index() == 0 ? 2 : 3;
  std::visit(
      [&](const auto& e) {
        r.sender = e.sender;
        r.seq = e.seq;
      },
      d.edge);
  if (dim_ != 0 && dim != dim_) {
    return reject(std::move(r), "dim",
                  "a " + std::to_string(dim) + "D edge on a " + std::to_string(dim_) + "D stream");
  }
  Sender& s = senders_[r.sender];
  const std::uint64_t fp = fingerprint(data, size);
  const auto seen = s.fingerprints.find(r.seq);
  if (seen != s.fingerprints.end()) {
    if (seen->second == fp) {
      r.verdict = Intake::kDuplicate;
      r.reason = "duplicate";
      ++counts_.duplicates;
      return r;
    }
    return reject(std::move(r), "seq reused",
                  "seq " + std::to_string(r.seq) + " of sender " + std::to_string(r.sender) +
                      " was already received with other contents");
  }
  if (r.seq > s.highest) {
    r.skipped = r.seq - s.highest - 1;
    counts_.gaps += r.skipped;
    s.highest = r.seq;
  } else {
    --counts_.gaps;  // a late edge fills a gap reported before
  }
  s.fingerprints.emplace(r.seq, fp);
  if (dim_ == 0) dim_ = dim;
  r.verdict = Intake::kAccepted;
  r.edge = std::move(d.edge);
  ++counts_.accepted;
  return r;
}

}  // namespace arbor::serve
