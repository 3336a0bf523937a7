// The journal seam of the streaming core: where every accepted measurement is written before it
// is applied, with the marks of the update grouping and every reseed's values, and what a restart
// reads back to reproduce the estimate bit for bit. The LCM event log (tools/serve/lcm_journal.h)
// is one implementation; any other keeps the same contract:
//  - append*() either keeps the whole entry or nothing of it, and throws std::runtime_error when
//    it keeps nothing (a full disk): the core then refuses the measurement, or holds the update;
//  - marks may use room that measurements may not (so what was journaled can still be applied);
//  - replay() hands back every entry in the order written, then appends after the last whole one.
#pragma once

#include <cstdint>
#include <functional>
#include <string>

#include "arbor_slam/tools/serve/stream_types.h"

namespace arbor::serve {

/// One entry read back from a journal, in file order.
struct JournalEntry {
  enum class Type {
    kMeasurement,  ///< an accepted edge, prior or edge command (`arrival`)
    kUpdateMark,   ///< the next `measurements` not yet covered by a mark went into one update
    kRefineMark,   ///< a refinement (relinearise all, iterate) ran here
    kReseed,       ///< the complete new linearisation point `seed` was applied here
    kUnreadable,   ///< an entry that could not be used (`problem` says why): skipped
  };
  Type type = Type::kUnreadable;
  Arrival arrival;       ///< kMeasurement (`wire` null: the entry's lifetime ends with it)
  int measurements = 0;  ///< kUpdateMark; kRefineMark: 0, or the cut (appendMark)
  Estimate seed;         ///< kReseed
  std::string problem;   ///< kUnreadable
};

/// What a replay found damaged and skipped (JournalSink::damage()).
struct JournalDamage {
  std::int64_t events = 0;      ///< events that failed their checksum or header: not replayed
  std::int64_t tail_bytes = 0;  ///< bytes after the last whole event, dropped (torn or damaged)
  std::int64_t unchecked = 0;   ///< events replayed without a checksum (written before them)
};

class JournalSink {
 public:
  virtual ~JournalSink() = default;
  /// Reads every entry written so far into `entry`, in order, reporting damage and torn tails
  /// through `note`, then opens the journal to append after the last whole entry. Called once,
  /// before any append. Throws std::runtime_error if the journal cannot be used.
  virtual void replay(const std::function<void(JournalEntry&&)>& entry,
                      const std::function<void(const std::string&)>& note) = 0;
  /// An accepted measurement (its bytes as received when `arrival.wire` is set).
  virtual void appendMeasurement(const Arrival& arrival) = 0;
  /// An update of `measurements` entries (kUpdateMark) or a refinement (kRefineMark;
  /// `measurements` 0: it ran to convergence, k > 0: it was cut short after k − 1 passed
  /// cancellation checks), after `update` updates; may use the room kept for marks.
  virtual void appendMark(JournalEntry::Type type, int measurements, std::int64_t update) = 0;
  /// A reseed's complete linearisation point, before it is applied.
  virtual void appendReseed(const Estimate& seed) = 0;
  /// fsync now / when the fsync interval has passed (no-ops where that means nothing).
  virtual void sync() = 0;
  virtual void syncIfDue() = 0;
  /// What the replay skipped (after replay(); none for a journal that cannot be damaged).
  virtual JournalDamage damage() const { return {}; }
  /// The journal's size in bytes (status).
  virtual std::int64_t bytes() const = 0;
  /// Its name in log lines (the file's path).
  virtual std::string name() const = 0;
};

}  // namespace arbor::serve
