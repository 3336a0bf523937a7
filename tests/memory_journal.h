// A JournalSink held in memory, for tests of the streaming core (tools/serve/journal_sink.h):
// the entries as the core wrote them, shared with the test so that a second core can be
// started from them.
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "arbor_slam/tools/serve/journal_sink.h"

namespace arbor::serve {

/// A journal held in memory: the entries as the core wrote them, shared with the test so that
/// a second core can be started from them.
class MemoryJournal final : public JournalSink {
 public:
  explicit MemoryJournal(std::shared_ptr<std::vector<JournalEntry>> entries)
      : entries_(std::move(entries)) {}
  void replay(const std::function<void(JournalEntry&&)>& entry,
              const std::function<void(const std::string&)>&) override {
    for (JournalEntry e : *entries_) entry(std::move(e));  // copies: the journal keeps them
  }
  void appendMeasurement(const Arrival& arrival) override {
    JournalEntry e;
    e.type = JournalEntry::Type::kMeasurement;
    e.arrival = arrival;
    e.arrival.wire = nullptr;
    e.arrival.wire_size = 0;
    entries_->push_back(std::move(e));
  }
  void appendMark(JournalEntry::Type type, int measurements, std::int64_t) override {
    JournalEntry e;
    e.type = type;
    e.measurements = measurements;
    entries_->push_back(std::move(e));
  }
  void appendReseed(const Estimate& seed) override {
    JournalEntry e;
    e.type = JournalEntry::Type::kReseed;
    e.seed = seed;
    entries_->push_back(std::move(e));
  }
  void sync() override {}
  void syncIfDue() override {}
  std::int64_t bytes() const override { return static_cast<std::int64_t>(entries_->size()); }
  std::string name() const override { return "memory"; }

 private:
  std::shared_ptr<std::vector<JournalEntry>> entries_;
};

}  // namespace arbor::serve
