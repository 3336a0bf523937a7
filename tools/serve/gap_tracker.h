// Loss recovery on the receive side of `arbor serve` (docs/lcm.md, "Loss recovery"): per sender
// and stream (edges, priors), what the intake accepted is released to the journal and the
// smoother in seq order. A message that arrives after a gap is held (a bounded reorder buffer)
// until the gap is filled by the sender's resend, so odometry is applied in the order sent and
// the estimate is the one an unbroken stream gives. The tracker also says what to ask for: per
// sender the missing seq ranges (resend requests, at most kMaxResendRanges a message), which
// double as a cumulative acknowledgement (`settled`).
// A gap is given up — counted, its held messages released in order — when
//  - it has waited `hold` since the first message above it arrived, counting only the time its
//    sender was heard from (a message within the last kQuiet): a link outage pauses the wait,
//    so a stream rides through an outage longer than `hold`, and the sender's resends fill the
//    gap once the link is back;
//  - it has waited kSilentFactor × `hold` however quiet the sender (one that ended, and does not
//    resend);
//  - the sender's answer says it no longer holds those seq numbers (giveUpTo),
//  - more than `limit` messages of that sender are held (memory), or
//  - a seq would need to be requested that the intake's window refuses as stale anyway.
// A message accepted after its gap was given up (late, still inside the intake's window) is
// released at once, out of order: applied once, never lost. The intake stays the judge of
// duplicates; the tracker only orders what it accepted (each seq is released once).
// Not thread-safe: the caller's lock (the intake's).
#pragma once

#include <chrono>
#include <cstddef>
#include <cstdint>
#include <map>
#include <utility>
#include <vector>

#include "arbor_slam/tools/serve/edge_intake.h"

namespace arbor::serve {

/// What serve asks one sender for (resend_t REQUEST): its stream's missing seq ranges.
struct ResendRequest {
  MeasurementKind kind = MeasurementKind::kEdge;  ///< kEdge or kPrior
  std::int64_t sender = 0;
  std::int64_t settled = 0;  ///< every seq <= settled is released or given up
  std::int64_t highest = 0;  ///< the highest seq accepted
  std::vector<std::pair<std::int64_t, std::int64_t>> missing;  ///< [first, last], ascending
};

struct GapCounts {
  std::int64_t held = 0;           ///< messages held now, waiting for a gap before them
  std::int64_t reordered = 0;      ///< messages released after waiting for a gap to fill
  std::int64_t given_up = 0;       ///< seq numbers given up (never received in time)
  std::int64_t gaps_given_up = 0;  ///< gaps (runs of seq numbers) given up
  std::int64_t late = 0;           ///< messages accepted after their gap was given up
  std::int64_t requests = 0;       ///< resend requests made (requests())
};

class GapTracker {
 public:
  using Clock = std::chrono::steady_clock;
  /// A sender not heard from for this long is quiet: its gaps' wait is paused.
  static constexpr std::chrono::milliseconds kQuiet{500};
  static constexpr int kSilentFactor = 10;
  /// `hold` <= 0: off (every message released at once, nothing requested). `limit` >= 1:
  /// messages held per sender and stream. `window`: the intake's (a seq that far below the
  /// highest is stale, never requested).
  GapTracker(Clock::duration hold, std::size_t limit, std::int64_t window);

  bool on() const { return hold_ > Clock::duration::zero(); }

  /// An accepted edge or prior (`r.wire` holding its bytes when it may be held): what to
  /// journal and apply now, in order (r itself, or nothing while it waits, or r and the held
  /// messages it unblocked). `given_up` (if given) gets the seq numbers this call gave up.
  std::vector<IntakeResult> offer(IntakeResult r, Clock::time_point now,
                                  std::int64_t* given_up = nullptr);
  /// The sender sent something (accepted, duplicate or held by the intake): acknowledged at the
  /// next requests().
  void heard(MeasurementKind kind, std::int64_t sender, Clock::time_point now);
  /// Gives up the gaps that waited `hold`; releases what they held. `given_up` (if given) gets
  /// the seq numbers given up.
  std::vector<IntakeResult> expire(Clock::time_point now, std::int64_t* given_up = nullptr);
  /// The sender holds nothing at or below `settled` (its WINDOW answer): the gaps there are
  /// given up.
  std::vector<IntakeResult> giveUpTo(MeasurementKind kind, std::int64_t sender,
                                     std::int64_t settled, std::int64_t* given_up = nullptr);
  /// Everything held, in order, every gap before it given up (stop()).
  std::vector<IntakeResult> releaseAll(std::int64_t* given_up = nullptr);
  /// The sender's table is gone from the intake (evicted): what it held, released.
  std::vector<IntakeResult> forget(MeasurementKind kind, std::int64_t sender);
  /// After a journal replay: `sender`'s stream is settled up to `highest` (what it journaled).
  void restore(MeasurementKind kind, std::int64_t sender, std::int64_t highest);

  /// The requests due: one per sender and stream with a gap, or heard from since the last
  /// call (an acknowledgement); heard flags cleared.
  std::vector<ResendRequest> requests();

  GapCounts counts() const { return counts_; }
  /// Seq numbers settled for `sender` (0 when unknown).
  std::int64_t settled(MeasurementKind kind, std::int64_t sender) const;

 private:
  struct Held {
    IntakeResult r;
    Clock::time_point arrived;
    Clock::duration waited_from{0};  ///< the sender's clock when it arrived
  };
  struct Sender {
    std::int64_t next = 1;     ///< the lowest seq neither released nor given up
    std::int64_t highest = 0;  ///< the highest seq accepted
    std::map<std::int64_t, Held> held;
    bool heard = false;
    Clock::time_point last_heard;
    Clock::duration clock{0};  ///< time this sender was heard from (advanced by expire())
  };
  using Id = std::pair<int, std::int64_t>;  ///< (kind, sender)
  static Id idOf(MeasurementKind kind, std::int64_t sender) {
    return {static_cast<int>(kind), sender};
  }
  /// Releases the run of held messages from s.next on.
  void drain(Sender& s, std::vector<IntakeResult>& out);
  /// Gives up the gap in front of s's first held message (or up to `to`), then drains.
  void giveUpHead(Sender& s, std::int64_t to, std::vector<IntakeResult>& out,
                  std::int64_t* given_up);

  Clock::duration hold_;
  Clock::time_point last_tick_;
  bool ticked_ = false;
  std::size_t limit_;
  std::int64_t window_;
  std::map<Id, Sender> senders_;
  GapCounts counts_;
};

}  // namespace arbor::serve
