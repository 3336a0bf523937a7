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
// No single message moves shared state (issue 56):
//  - a seq more than jumpLimit() above its sender's highest (a "jump": a forged seq 2^62 would
//    make every real seq stale) is held, not applied, and does not move the highest seq until it
//    is confirmed: the sender's held messages cover kConfirmRun consecutive seq numbers s, s+1,
//    …, s+kConfirmRun−1 (any order). They are then accepted together (the current message's
//    result carries the others in `released`). A message of that sender accepted inside its
//    window meanwhile, or a jump outside [s, s+kConfirmRun), drops what was held ("unconfirmed
//    jump"). A sender's first message counts from highest 0.
//    Edge commands are the exception: `arbor command` numbers them by the clock (ms), so each is
//    a jump; one beyond jumpLimit() is accepted at once (one operator action, idempotent) and
//    remembered among the sender's last kRecentJumps such seqs (duplicates, "seq reused"), but
//    it never moves the highest seq either.
//  - sender tables are bounded (`max_senders` per stream), and a new sender takes the place of
//    the least recently heard one (evicted, counted) instead of being refused. An evicted sender
//    that comes back starts afresh: its next seq above jumpLimit() must be confirmed.
//  - gap counts saturate at INT64_MAX instead of overflowing.
// Worst case memory: 3 streams x max_senders x (window x 8 bytes + kConfirmRun − 1 held messages).
// Not thread-safe: one thread (the receive thread, or the journal replay before it starts).
#pragma once

#include <chrono>
#include <cstddef>
#include <cstdint>
#include <map>
#include <string>
#include <unordered_map>
#include <utility>
#include <vector>

#include "arbor_slam/io/stream_measurements.h"
#include "arbor_slam/tools/serve/stream_types.h"

namespace arbor::serve {

enum class Intake {
  kAccepted,   ///< valid and new: to be journaled and applied
  kDuplicate,  ///< byte-for-byte repeat of an earlier (sender, seq): dropped
  kRejected,   ///< invalid, or "stale" (below the sender's window): dropped, counted under `reason`
  kHeld,       ///< a seq jump waiting for its confirmation: neither journaled nor applied yet
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
  std::uint64_t fingerprint = 0;     ///< as admitted
  /// Accepted with this one: the held messages its arrival confirmed, in the order received
  /// (each kAccepted, with `wire` the bytes it arrived with, empty if none were given).
  std::vector<IntakeResult> released;
  std::vector<unsigned char> wire;  ///< a released message's bytes as received
  std::int64_t dropped = 0;         ///< held messages this arrival dropped ("unconfirmed jump")
  std::int64_t evicted = 0;         ///< the sender whose table this arrival's sender took (0: none)
  /// When it arrived, if the caller holds it before applying it (the streaming core's loss
  /// recovery: its latency counts from here); default: unset.
  std::chrono::steady_clock::time_point arrived{};
};

struct IntakeCounts {
  std::int64_t received = 0;
  std::int64_t accepted = 0;
  std::int64_t rejected = 0;
  std::int64_t duplicates = 0;
  std::int64_t gaps = 0;  ///< seq numbers skipped by senders and not received since (saturates)
  std::int64_t held = 0;  ///< messages held now, waiting for their jump's confirmation
  std::int64_t jumps_confirmed = 0;  ///< seq jumps confirmed (the highest seq moved)
  std::int64_t senders_evicted = 0;  ///< sender tables given to a new sender (least recently heard)
  std::map<std::string, std::int64_t> rejected_by_reason;
};

class EdgeIntake {
 public:
  static constexpr std::int64_t kDefaultWindow = 65536;
  static constexpr std::size_t kDefaultMaxSenders = 64;
  /// The largest seq advance applied at once is window − 1 (jumpLimit()): the largest after
  /// which every seq the sender sent before and we have not received yet is still inside the
  /// window, so one message never makes a real seq stale. A 1,000-message limit (10 s at 100 Hz)
  /// was measured to hold a lone message sent after a udpm burst lost more than 1,000, with
  /// nothing after it to confirm it (tests/lcm_process_test.cc, BurstLossIsAllReportedAsGaps).
  /// Consecutive seq numbers that confirm a jump: any run >= 2 defeats one forged message; 3 also
  /// defeats a forged message repeated once under the next seq, and costs a sender that truly
  /// jumped (a restart without the journal, an evicted table) two messages of delay.
  static constexpr int kConfirmRun = 3;
  /// Edge commands accepted beyond the jump limit, remembered per sender (16 · 16 bytes).
  static constexpr std::size_t kRecentJumps = 16;

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
  /// `wire`: the bytes it arrived with, kept while it is held (may be null).
  IntakeResult admitEdge(AnyStreamEdge edge, std::uint64_t fingerprint, const void* wire = nullptr,
                         int wire_size = 0);
  IntakeResult admitPrior(AnyStreamPrior prior, std::uint64_t fingerprint,
                          const void* wire = nullptr, int wire_size = 0);
  IntakeResult admitCommand(const StreamEdgeCommand& command, std::uint64_t fingerprint,
                            const void* wire = nullptr, int wire_size = 0);
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
  /// Per sender of `kind`: (sender, its highest seq), in sender order.
  std::vector<std::pair<std::int64_t, std::int64_t>> highestBySender(Kind kind) const;
  /// Sender tables held per stream (each <= max_senders()).
  std::size_t senders(Kind kind) const;
  std::size_t maxSenders() const { return max_senders_; }
  /// max(1, window − 1).
  std::int64_t jumpLimit() const { return jump_limit_; }

 private:
  struct Sender {
    std::int64_t highest = 0;  ///< highest seq seen (seq numbers start at 1)
    std::int64_t gaps = 0;     ///< seq numbers below highest not received (or revoked)
    /// Ring over the window: slot (seq − 1) mod W holds the hash of seq's bytes, 0 = not
    /// received. Grown on demand up to W slots.
    std::vector<std::uint64_t> ring;
    std::uint64_t heard = 0;         ///< the intake's message count when last heard from
    std::int64_t jump_from = 0;      ///< the held jump's first seq
    std::vector<IntakeResult> held;  ///< its messages (< kConfirmRun)
    /// Edge commands accepted beyond the jump limit: (seq, fingerprint), oldest first.
    std::vector<std::pair<std::int64_t, std::uint64_t>> jumped;
  };
  /// One kind of message: its senders' seq tables and its counts.
  struct Stream {
    std::unordered_map<std::int64_t, Sender> senders;
    IntakeCounts counts;
  };
  IntakeResult reject(Stream& stream, IntakeResult r, const std::string& reason,
                      const std::string& detail);
  /// A seq seen before (`where`: "was already received", "is held"): a duplicate when its
  /// contents are the same, else refused as "seq reused".
  IntakeResult repeated(Stream& stream, IntakeResult r, bool same_contents,
                        const std::string& where);
  /// The seq accounting of a decoded message of `dim` (r.sender, r.seq set): accepted,
  /// duplicate or rejected ("dim", "stale", "seq reused").
  IntakeResult admitSeq(Stream& stream, IntakeResult r, int dim, std::uint64_t contents,
                        const void* wire, int wire_size);
  /// r's sender's table, made (taking the least recently heard one's place when full).
  Sender& table(Stream& stream, IntakeResult& r);
  /// A seq beyond jumpLimit(): held, or the run that confirms the jump.
  IntakeResult holdJump(Stream& stream, Sender& s, IntakeResult r, std::uint64_t fp,
                        const void* wire, int wire_size);
  /// An edge command beyond jumpLimit(): accepted unless a duplicate or a reused seq.
  IntakeResult acceptJumpedCommand(Stream& stream, Sender& s, IntakeResult r, std::uint64_t fp);
  /// Drops what `s` holds (counted "unconfirmed jump"); how many.
  std::int64_t dropHeld(Stream& stream, Sender& s);
  std::uint64_t* slot(Sender& s, std::int64_t seq, bool grow) const;
  void advance(Sender& s, std::int64_t seq) const;

  Stream& stream(Kind kind);
  int dim_;
  std::int64_t window_;
  std::size_t max_senders_;
  std::int64_t jump_limit_;
  std::uint64_t heard_ = 0;  ///< messages seen, as the senders' clock
  Stream edges_, priors_, commands_;
};

}  // namespace arbor::serve
