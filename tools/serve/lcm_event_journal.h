// The streaming core's journal as an LCM event log (io/lcm_journal.h; what lcm-logger writes and
// lcm-logplayer plays): every accepted measurement as its bytes as received (edge_t or
// edge_v1_t, prior_t, edge_command_t) on its channel, the update marks as journal_mark_t on
// ARBOR_JOURNAL_MARK, each reseed's point as a full estimate_t on ARBOR_JOURNAL_RESEED. Read back,
// events are told apart by their type hash. Every event carries a checksum (io/lcm_journal.h): a
// damaged one is skipped, counted (damage()) and logged, never replayed. docs/lcm.md, "Journal".
#pragma once

#include <cstdint>
#include <memory>
#include <string>

#include "arbor_slam/io/lcm_journal.h"
#include "arbor_slam/tools/serve/journal_sink.h"
#include "arbor_slam/tools/serve/lcm_channels.h"

namespace arbor::serve {

class LcmEventJournal final : public JournalSink {
 public:
  /// The log at `path` (created by replay() if missing); measurements go on `channels`' edge,
  /// prior and edge-command channels.
  LcmEventJournal(std::string path, Channels channels, EventLogWriterOptions options);
  void replay(const std::function<void(JournalEntry&&)>& entry,
              const std::function<void(const std::string&)>& note) override;
  void appendMeasurement(const Arrival& arrival) override;
  void appendMark(JournalEntry::Type type, int measurements, std::int64_t update) override;
  void appendReseed(const Estimate& seed) override;
  void sync() override;
  void syncIfDue() override;
  JournalDamage damage() const override { return damage_; }
  std::int64_t bytes() const override;
  std::string name() const override { return path_; }

 private:
  EventLogWriter& writer();
  /// Logs what the reading skipped (damage, a torn tail, unchecked events) and keeps the counts.
  void reportDamage(const EventLogContents& log,
                    const std::function<void(const std::string&)>& note);
  std::string path_;
  Channels channels_;
  EventLogWriterOptions options_;
  std::unique_ptr<EventLogWriter> writer_;
  JournalDamage damage_;
};

}  // namespace arbor::serve
