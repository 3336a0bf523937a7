#include "arbor_slam/tools/serve/lcm_event_journal.h"

#include <stdexcept>
#include <utility>
#include <vector>

#include "arbor_slam/io/lcm_messages.h"
#include "arbor_slam/tools/serve/lcm_mapping.h"

namespace arbor::serve {
namespace {

std::int64_t leadingHash(const std::vector<std::uint8_t>& data) {
  std::int64_t h = 0;
  for (size_t k = 0; k < 8 && k < data.size(); ++k) h = (h << 8) | data[k];
  return data.size() < 8 ? 0 : h;
}

/// A measurement's bytes when the transport kept none: its LCM message.
std::vector<std::uint8_t> encodeMeasurement(const Arrival& a) {
  switch (a.kind) {
    case MeasurementKind::kPrior:
      return std::visit([](const auto& p) { return encodeMessage(makePriorMessage(p)); }, a.prior);
    case MeasurementKind::kCommand:
      return encodeMessage(makeEdgeCommandMessage(a.command));
    case MeasurementKind::kEdge:
      break;
  }
  return std::visit([](const auto& e) { return encodeMessage(makeEdgeMessage(e)); }, a.edge);
}

/// Damaged stretches logged one line each, up to this many; the rest in one line.
constexpr size_t kDamageLines = 10;

}  // namespace

void LcmEventJournal::reportDamage(const EventLogContents& log,
                                   const std::function<void(const std::string&)>& note) {
  damage_.events = log.damaged_events;
  damage_.tail_bytes = log.file_bytes - log.valid_bytes;
  damage_.unchecked = log.unchecked_events;
  const std::string where = "journal " + path_ + ": ";
  std::int64_t more_events = 0;
  for (size_t k = 0; k < log.damaged.size(); ++k) {
    const auto [first, end] = log.damaged[k];
    if (k >= kDamageLines) {
      more_events += end - first;
      continue;
    }
    note(where + "bytes " + std::to_string(first) + " to " + std::to_string(end) +
         " are damaged (at byte " + std::to_string(first) + ": " + log.damage_reasons[k] +
         "); skipped, not replayed; the events after them are replayed and the bytes stay in "
         "the file");
  }
  if (log.damaged.size() > kDamageLines) {
    note(where + std::to_string(log.damaged.size() - kDamageLines) + " more damaged stretches (" +
         std::to_string(more_events) + " bytes) skipped");
  }
  if (damage_.tail_bytes > 0) {
    note(where + "dropping the " + std::to_string(damage_.tail_bytes) + " bytes after byte " +
         std::to_string(log.valid_bytes) +
         ", the end of the last whole event (there: " + log.tail_reason + ")");
  }
  if (damage_.events > 0) {
    note(where + std::to_string(damage_.events) + " damaged events skipped in all");
  }
  if (damage_.unchecked > 0) {
    note(where + "the first " + std::to_string(damage_.unchecked) +
         " events were written before events carried checksums (an older arbor): replayed "
         "unchecked, damage in them cannot be told; the events appended from now on are "
         "checksummed (a journal started anew is checked throughout)");
  }
}

LcmEventJournal::LcmEventJournal(std::string path, Channels channels, EventLogWriterOptions options)
    : path_(std::move(path)), channels_(std::move(channels)), options_(options) {}

EventLogWriter& LcmEventJournal::writer() {
  if (!writer_) throw std::logic_error("journal " + path_ + ": appended to before replay()");
  return *writer_;
}

void LcmEventJournal::replay(const std::function<void(JournalEntry&&)>& entry,
                             const std::function<void(const std::string&)>& note) {
  const EventLogContents log = readEventLog(path_);
  reportDamage(log, note);
  const std::int64_t prior_hash = prior_t::getHash();
  const std::int64_t command_hash = edge_command_t::getHash();
  const std::int64_t mark_hash = journal_mark_t::getHash();
  const std::int64_t reseed_hash = estimate_t::getHash();
  for (const LogEvent& event : log.events) {
    const std::int64_t hash = leadingHash(event.data);
    const int size = static_cast<int>(event.data.size());
    JournalEntry e;
    if (isEdgeMessage(event.data.data(), size) || hash == prior_hash || hash == command_hash) {
      const MeasurementKind kind = hash == prior_hash     ? MeasurementKind::kPrior
                                   : hash == command_hash ? MeasurementKind::kCommand
                                                          : MeasurementKind::kEdge;
      e.type = JournalEntry::Type::kMeasurement;
      e.arrival = arrivalFromBytes(kind, event.data.data(), size);
      e.arrival.wire = nullptr;  // the event's bytes do not outlive this loop
      e.arrival.wire_size = 0;
    } else if (hash == mark_hash) {
      journal_mark_t m;
      if (decodeMessage(event.data.data(), size, &m) != MessageProblem::kNone) continue;
      if (m.kind == journal_mark_t::UPDATE) {
        e.type = JournalEntry::Type::kUpdateMark;
        e.measurements = m.edges;
      } else if (m.kind == journal_mark_t::REFINE) {
        e.type = JournalEntry::Type::kRefineMark;
        e.measurements = m.edges;  // 0: to convergence; k > 0: cut after k − 1 checks
      } else {
        continue;
      }
    } else if (hash == reseed_hash && event.channel == kJournalReseedChannel) {
      estimate_t seed;
      if (decodeMessage(event.data.data(), size, &seed) != MessageProblem::kNone) {
        e.type = JournalEntry::Type::kUnreadable;
        e.problem = "a reseed record could not be used";
      } else {
        e.type = JournalEntry::Type::kReseed;
        e.seed = fromMessage(seed);
      }
    } else {
      continue;  // not ours (e.g. lcm-logger's other channels)
    }
    entry(std::move(e));
  }
  writer_ = std::make_unique<EventLogWriter>(path_, log.valid_bytes, options_);
}

void LcmEventJournal::appendMeasurement(const Arrival& a) {
  const std::string& channel = a.kind == MeasurementKind::kPrior     ? channels_.priors
                               : a.kind == MeasurementKind::kCommand ? channels_.edge_commands
                                                                     : channels_.edges;
  if (a.wire != nullptr) {
    writer().append(channel, nowMicros(), a.wire, a.wire_size);
    return;
  }
  const std::vector<std::uint8_t> bytes = encodeMeasurement(a);
  writer().append(channel, nowMicros(), bytes.data(), static_cast<int>(bytes.size()));
}

void LcmEventJournal::appendMark(JournalEntry::Type type, int measurements, std::int64_t update) {
  journal_mark_t m;
  m.utime = nowMicros();
  m.kind =
      type == JournalEntry::Type::kRefineMark ? journal_mark_t::REFINE : journal_mark_t::UPDATE;
  m.edges = measurements;
  m.update = update;
  const auto bytes = encodeMessage(m);
  writer().append(kJournalMarkChannel, m.utime, bytes.data(), static_cast<int>(bytes.size()),
                  EventClass::kRecord);
}

void LcmEventJournal::appendReseed(const Estimate& seed) {
  const auto bytes = encodeMessage(toMessage(seed));
  writer().append(kJournalReseedChannel, seed.utime, bytes.data(), static_cast<int>(bytes.size()));
}

void LcmEventJournal::sync() { writer().sync(); }
void LcmEventJournal::syncIfDue() { writer().syncIfDue(); }
std::int64_t LcmEventJournal::bytes() const { return writer_ ? writer_->bytes() : 0; }

}  // namespace arbor::serve
