// The journal of `arbor serve`: an LCM event log (the format lcm-logger writes and lcm-logplayer
// plays) whose events each carry a CRC-32 in their event-number field, read and written here
// (not with liblcm's lcm_eventlog API, whose reader allocates from an unchecked length field).
// Bytes only: what the events mean (edge_t, journal_mark_t) is up to the caller.
//
// An event on disk, big-endian: sync word 0xEDA1DA01, event number (8 bytes), timestamp (8),
// channel length (4), data length (4), channel, data. The event number's high 32 bits are
// kEventChecksumTag and its low 32 bits zlib's crc32 of everything after it (timestamp, both
// lengths, channel, data). lcm-logplayer ignores the event number, so it still plays the log.
// A log written before the checksum (event numbers 0, 1, 2, …: high bits 0) is read unchecked up
// to its first checksummed event; after that an event without the tag is damage.
#pragma once

#include <cstdint>
#include <cstdio>
#include <mutex>
#include <string>
#include <utility>
#include <vector>

namespace arbor {

/// The high 32 bits of a checksummed event's event number ("ARB1").
inline constexpr std::uint32_t kEventChecksumTag = 0x41524231;

struct LogEvent {
  std::string channel;
  std::int64_t timestamp = 0;  ///< µs since the epoch
  std::vector<std::uint8_t> data;
  std::int64_t offset = 0;  ///< file offset of its sync word
  bool checked = true;      ///< its checksum verified (false: an event written before them)
};

struct EventLogContents {
  std::vector<LogEvent> events;  ///< every complete event found, in file order
  std::int64_t valid_bytes = 0;  ///< file offset just after the last complete event
  std::int64_t file_bytes = 0;   ///< > valid_bytes when the tail is torn (e.g. after kill -9)
  /// Byte ranges [first, second) that are not events but have complete events after them
  /// (damage inside the file, not a torn tail): skipped, the reading resumed at the next
  /// event's sync word. Empty for a sound log. They lie before valid_bytes, so a writer opened
  /// at valid_bytes keeps them, and every event after them, in the file.
  std::vector<std::pair<std::int64_t, std::int64_t>> damaged;
  /// For each damaged stretch, what its first bytes failed, with the value read (e.g.
  /// "checksum 0x…, the bytes give 0x…", "data length 2147483647 runs past the end …").
  std::vector<std::string> damage_reasons;
  /// What the bytes after valid_bytes failed (empty when there are none).
  std::string tail_reason;
  /// Events skipped as damaged: one per damaged stretch, or one per event start (sync word) in
  /// it when it holds several; at the end, every event start in the tail that is not a torn
  /// (incomplete) last write.
  std::int64_t damaged_events = 0;
  /// The tail after valid_bytes ends in an incomplete event (a write cut short: kill -9).
  bool torn_tail = false;
  /// Events read without a checksum (written before checksums: a prefix of the log).
  std::int64_t unchecked_events = 0;
};

/// Reads an LCM event log: every complete event whose checksum verifies, skipping damaged
/// stretches (see EventLogContents::damaged), up to a damaged or torn tail. Lengths are checked
/// against the file before anything is read from them. A missing file is empty. Throws
/// std::runtime_error if the file exists but cannot be read.
EventLogContents readEventLog(const std::string& path);

struct EventLogWriterOptions {
  /// fsync after every event (0), at most every this many ms (> 0; sync() / syncIfDue() cover
  /// the tail), or never (< 0: the OS decides). Every event is fflush'ed to the kernel at once,
  /// so a killed process loses nothing either way; fsync guards against power loss.
  int fsync_interval_ms = 0;
  /// > 0: the log may not grow past this many bytes; an event that would end past it is
  /// refused as on a full disk (errno ENOSPC), nothing of it written. 0: no limit.
  std::int64_t max_bytes = 0;
  /// Room kept for records (EventClass::kRecord, e.g. the update marks that make journaled
  /// measurements appliable) that measurements may not use. With max_bytes, measurements stop
  /// this far short of it. On the disk, a spare file `<path>.reserve` of this size holds the room:
  /// when a record meets a full disk the spare file is deleted and the record written; from
  /// then on measurements are refused until the spare file can be made again (tried on each
  /// measurement). 0: no reserve.
  std::int64_t reserve_bytes = 0;
};

/// Whether an event may use the reserve (EventLogWriterOptions::reserve_bytes).
enum class EventClass {
  kMeasurement,  ///< refused once only the reserve is left
  kRecord,       ///< may use the reserve
};

/// Appends events to an LCM event log. Thread-safe (one mutex).
/// A failed write leaves the log as it was: the file is cut back to the end of the last event
/// that was written whole and stdio's buffer is dropped, so a full disk (ENOSPC) or the
/// max_bytes limit never leaves a torn event or a later write of the refused one; the next
/// append() tries again (space may have been freed).
class EventLogWriter {
 public:
  /// Opens `path` for appending (creating it); when `valid_bytes` ≥ 0 the file is first cut to
  /// that length (drops a torn tail). Throws std::runtime_error if it cannot.
  EventLogWriter(const std::string& path, std::int64_t valid_bytes,
                 EventLogWriterOptions options = {});
  ~EventLogWriter();
  EventLogWriter(const EventLogWriter&) = delete;
  EventLogWriter& operator=(const EventLogWriter&) = delete;

  /// Writes one event and flushes it to the kernel; fsyncs per the policy. Throws
  /// std::runtime_error on a write error (nothing of the event stays in the file).
  void append(const std::string& channel, std::int64_t timestamp, const void* data, int size,
              EventClass kind = EventClass::kMeasurement);
  /// fsync now if anything was written since the last fsync.
  void sync();
  /// sync() if the fsync interval has passed since the last one.
  void syncIfDue();
  std::int64_t eventsWritten() const;
  /// The file's length: the end of the last event written whole.
  std::int64_t bytes() const;
  /// Appends refused (write errors and the max_bytes limit).
  std::int64_t failures() const;
  const std::string& path() const { return path_; }

 private:
  void syncLocked();
  /// Cuts the file back to bytes_ after a failed write and drops stdio's buffer.
  void rollBack();
  /// Writes the event; false (errno set, file rolled back) on failure.
  bool writeEvent(const std::string& channel, std::int64_t timestamp, const void* data, int size);
  /// Makes the spare file of reserve_bytes; false if the disk has no room for it.
  bool makeReserve();
  std::string path_;
  EventLogWriterOptions options_;
  std::FILE* file_ = nullptr;
  mutable std::mutex mutex_;
  std::int64_t written_ = 0;
  std::int64_t bytes_ = 0;  ///< file length after the last whole event
  std::int64_t failures_ = 0;
  std::string reserve_path_;
  bool reserve_held_ = false;  ///< the spare file exists (or no reserve is kept on disk)
  bool dirty_ = false;
  std::int64_t last_sync_us_ = 0;
};

}  // namespace arbor
