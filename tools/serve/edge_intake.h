// The receive side of `arbor serve`: decodes and validates each edge_t, prior_t and
// edge_command_t, tracks every sender's seq numbers (gaps, exact duplicates, reused seq numbers)
// and counts what it refused and why. Edges, priors and edge commands are three streams: each
// has its own per-sender seq numbers and its own counts (a front-end numbering them from one
// counter shows gaps in each, never a "seq reused" refusal); edges and priors share the stream's
// dimension (a command has none).
// Memory is bounded: per sender only the last `window` seq numbers are remembered (the highest
// seen and the W − 1 below it). A seq below that window is refused as "stale": it may be a late
// edge or a repeat of one applied long ago, and we cannot tell, so we never apply it (a repeat
// applied twice would silently count one measurement twice; a refused edge is counted and logged
// and can be sent again under a new seq).
// Sender tables are bounded too: at most `max_senders` per stream; a message from a sender beyond
// them is refused as "sender limit" (its table is never made), so a flood of made-up sender ids
// costs counts, not memory. Worst case: 3 streams x max_senders x window x 8 bytes.
// Not thread-safe: one thread (the receive thread, or the journal replay before it starts).
#pragma once

#include <cstddef>
#include <cstdint>
#include <map>
#include <string>
#include <unordered_map>
#include <utility>
#include <vector>

#include "arbor/io/stream_measurements.h"
#include "arbor/tools/serve/stream_types.h"

namespace arbor::serve {

enum class Intake {
  kAccepted,   ///< valid and new: to be journaled and applied
  kDuplicate,  ///< byte-for-byte repeat of an earlier (sender, seq): dropped
  kRejected,   ///< invalid, or "stale" (below the sender's window): dropped, counted under `reason`
};

struct IntakeResult {
  Intake verdict = Intake::kRejected;
  std::string reason;         ///< short reason ("truncated", "type hash", "nan", "seq reused", ...)
  std::string detail;         ///< the full explanation, for the log line
  bool is_prior = false;      ///< came through admitPrior
  bool is_command = false;    ///< came through admitCommand
  AnyStreamEdge edge;         ///< when an accepted edge
  AnyStreamPrior prior;       ///< when an accepted prior
  StreamEdgeCommand command;  ///< when an accepted edge command
  std::int64_t sender = 0, seq = 0;  ///< when decoded
  std::int64_t skipped = 0;          ///< seq numbers of this sender jumped over by this message
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
  static constexpr std::int64_t kDefaultWindow = 65536;
  static constexpr std::size_t kDefaultMaxSenders = 64;

  /// `dim` 2 or 3 fixes the stream's dimension; 0 takes it from the first accepted edge or
  /// prior. `window` (>= 1): how many of each sender's latest seq numbers are remembered
  /// exactly (per stream). `max_senders` (>= 1): sender tables per stream.
  explicit EdgeIntake(int dim = 0, std::int64_t window = kDefaultWindow,
                      std::size_t max_senders = kDefaultMaxSenders);

  /// An edge_t's bytes (decodeEdge, then admitEdge with the bytes' fingerprint).
  IntakeResult admit(const void* data, int size);
  /// A prior_t's bytes.
  IntakeResult admitPrior(const void* data, int size);
  /// An edge_command_t's bytes.
  IntakeResult admitCommand(const void* data, int size);
  /// A validated edge, whatever carried it: the seq accounting alone. `fingerprint` identifies
  /// the message's exact contents (duplicate against "seq reused"; fingerprint() of its bytes).
  IntakeResult admitEdge(AnyStreamEdge edge, std::uint64_t fingerprint);
  IntakeResult admitPrior(AnyStreamPrior prior, std::uint64_t fingerprint);
  IntakeResult admitCommand(const StreamEdgeCommand& command, std::uint64_t fingerprint);
  /// An arrival from a transport: refused under its `problem` when it has one, else admitted
  /// by its kind.
  IntakeResult admit(const Arrival& arrival);
  /// FNV-1a (64 bit) of a message's bytes: what the byte entry points use as its fingerprint.
  static std::uint64_t fingerprint(const void* data, int size);
  /// Takes back an accepted edge, prior or command that could not be kept (the journal write
  /// failed): counted as rejected under `reason`, and its (sender, seq) may be sent again.
  void revoke(const IntakeResult& accepted, const std::string& reason);
  using Kind = MeasurementKind;
  /// A message of `kind` refused before it was decoded (e.g. "oversize"): received and
  /// rejected under `reason`.
  void refuse(Kind kind, const std::string& reason);
  const IntakeCounts& counts() const { return edges_.counts; }            ///< edges
  const IntakeCounts& priorCounts() const { return priors_.counts; }      ///< priors
  const IntakeCounts& commandCounts() const { return commands_.counts; }  ///< edge commands
  int dim() const { return dim_; }
  std::int64_t window() const { return window_; }
  /// Edge seq slots held for `sender` (0 if unknown): never more than window().
  std::size_t trackedSeqs(std::int64_t sender) const;
  /// Per sender of `kind` with gaps: (sender, seq numbers not received), in sender order; the
  /// counts sum to the stream's IntakeCounts::gaps. At most max_senders() entries.
  std::vector<std::pair<std::int64_t, std::int64_t>> gapsBySender(Kind kind) const;
  /// Sender tables held per stream (each <= max_senders()).
  std::size_t senders(Kind kind) const;
  std::size_t maxSenders() const { return max_senders_; }

 private:
  struct Sender {
    std::int64_t highest = 0;  ///< highest seq seen (seq numbers start at 1)
    std::int64_t gaps = 0;     ///< seq numbers below highest not received (or revoked)
    /// Ring over the window: slot (seq − 1) mod W holds the hash of seq's bytes, 0 = not
    /// received. Grown on demand up to W slots.
    std::vector<std::uint64_t> ring;
  };
  /// One kind of message: its senders' seq tables and its counts.
  struct Stream {
    std::unordered_map<std::int64_t, Sender> senders;
    IntakeCounts counts;
  };
  IntakeResult reject(Stream& stream, IntakeResult r, const std::string& reason,
                      const std::string& detail);
  /// The seq accounting of a decoded message of `dim` (r.sender, r.seq set): accepted,
  /// duplicate or rejected ("dim", "stale", "seq reused").
  IntakeResult admitSeq(Stream& stream, IntakeResult r, int dim, std::uint64_t contents);
  std::uint64_t* slot(Sender& s, std::int64_t seq, bool grow) const;
  void advance(Sender& s, std::int64_t seq) const;

  Stream& stream(Kind kind);
  int dim_;
  std::int64_t window_;
  std::size_t max_senders_;
  Stream edges_, priors_, commands_;
};

}  // namespace arbor::serve
