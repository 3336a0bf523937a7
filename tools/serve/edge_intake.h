// The receive side of `arbor serve`: decodes and validates each edge_t, tracks every sender's
// seq numbers (gaps, exact duplicates, reused seq numbers) and counts what it refused and why.
// Not thread-safe: one thread (the receive thread, or the journal replay before it starts).
#pragma once

#include <cstdint>
#include <map>
#include <string>
#include <unordered_map>

#include "io/lcm_messages.h"

namespace arbor::serve {

enum class Intake {
  kAccepted,   ///< valid and new: to be journaled and applied
  kDuplicate,  ///< byte-for-byte repeat of an earlier (sender, seq): dropped
  kRejected,   ///< invalid: dropped, counted under `reason`
};

struct IntakeResult {
  Intake verdict = Intake::kRejected;
  std::string reason;  ///< short reason ("truncated", "type hash", "nan", "seq reused", ...)
  std::string detail;  ///< the full explanation, for the log line
  AnyStreamEdge edge;  ///< when accepted
  std::int64_t sender = 0, seq = 0;  ///< when decoded
  std::int64_t skipped = 0;          ///< seq numbers of this sender jumped over by this edge
};

struct IntakeCounts {
  std::int64_t received = 0;
  std::int64_t accepted = 0;
  std::int64_t rejected = 0;
  std::int64_t duplicates = 0;
  std::int64_t gaps = 0;  ///< seq numbers skipped by senders and not received since
  std::map<std::string, std::int64_t> rejected_by_reason;
};

class EdgeIntake {
 public:
  /// `dim` 2 or 3 fixes the stream's dimension; 0 takes it from the first accepted edge.
  explicit EdgeIntake(int dim = 0) : dim_(dim) {}

  IntakeResult admit(const void* data, int size);
  /// Takes back an accepted edge that could not be kept (the journal write failed): counted as
  /// rejected under `reason`, and its (sender, seq) may be sent again.
  void revoke(const IntakeResult& accepted, const std::string& reason);
  const IntakeCounts& counts() const { return counts_; }
  int dim() const { return dim_; }

 private:
  struct Sender {
    std::int64_t highest = 0;  ///< highest seq seen (seq numbers start at 1)
    std::unordered_map<std::int64_t, std::uint64_t> fingerprints;  ///< seq → hash of the bytes
  };
  IntakeResult reject(IntakeResult r, const std::string& reason, const std::string& detail);

  int dim_;
  std::unordered_map<std::int64_t, Sender> senders_;
  IntakeCounts counts_;
};

}  // namespace arbor::serve
