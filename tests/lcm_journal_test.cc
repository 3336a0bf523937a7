// The journal's event log reading its own damage (io/lcm_journal.h): every event carries a
// checksum, so a flipped byte anywhere costs exactly the event it falls in; a length field is
// checked against the file before anything is read from it (0x7FFFFFFF used to crash liblcm's
// reader); junk after the last event costs no event; a cut anywhere costs only the events it
// cuts; a log written by liblcm before checksums is still read, unchecked, up to its first
// checksummed event; liblcm (lcm-logplayer) still reads a checksummed log.
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <iterator>
#include <random>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include <lcm/eventlog.h>

#include "arbor_slam/io/lcm_journal.h"
#include "process_temp_dir.h"

namespace arbor {
namespace {

std::string tempPath(const std::string& name) {
  const std::string path = (testing::processTempDir() / name).string();
  std::remove(path.c_str());
  return path;
}

std::vector<char> readBytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

void writeBytes(const std::string& path, const std::vector<char>& bytes) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
}

/// `n` events of varied sizes on channels CH0, CH1, …; each event's [start, end) in the file.
std::vector<std::pair<std::int64_t, std::int64_t>> writeLog(const std::string& path, int n) {
  std::remove(path.c_str());
  {
    EventLogWriter w(path, -1);
    for (int k = 0; k < n; ++k) {
      const std::string payload(20 + (k * 37) % 90, static_cast<char>('a' + k % 26));
      w.append("CH" + std::to_string(k), 1000 + k, payload.data(),
               static_cast<int>(payload.size()));
    }
  }
  const EventLogContents c = readEventLog(path);
  EXPECT_EQ(c.events.size(), static_cast<size_t>(n));
  std::vector<std::pair<std::int64_t, std::int64_t>> spans;
  for (size_t k = 0; k < c.events.size(); ++k) {
    const std::int64_t end = k + 1 < c.events.size() ? c.events[k + 1].offset : c.valid_bytes;
    spans.emplace_back(c.events[k].offset, end);
  }
  return spans;
}

std::vector<std::string> channels(const EventLogContents& c) {
  std::vector<std::string> out;
  for (const LogEvent& e : c.events) out.push_back(e.channel);
  return out;
}

std::vector<std::string> channelsWithout(int n, int skipped) {
  std::vector<std::string> out;
  for (int k = 0; k < n; ++k)
    if (k != skipped) out.push_back("CH" + std::to_string(k));
  return out;
}

int eventAt(const std::vector<std::pair<std::int64_t, std::int64_t>>& spans, std::int64_t at) {
  for (size_t k = 0; k < spans.size(); ++k)
    if (at >= spans[k].first && at < spans[k].second) return static_cast<int>(k);
  return -1;
}

// 1,000 single-byte changes (ARBOR_JOURNAL_FLIPS sets how many; positions and values from a fixed
// seed, the value always differs): each costs exactly the event it falls in, counted; every other
// event is read. Inside the log the event is counted damaged; the last event's damage is dropped
// with the tail (counted in bytes: a length that now runs past the end reads as a write cut short).
TEST(LcmJournalDamage, EveryChangedByteCostsExactlyTheEventItFallsIn) {
  const int n = 40;
  const std::string path = tempPath("flip.lcmlog");
  const std::string copy = tempPath("flip.copy.lcmlog");
  const auto spans = writeLog(path, n);
  const std::vector<char> clean = readBytes(path);
  std::mt19937 rng(56);
  const int trials =
      std::getenv("ARBOR_JOURNAL_FLIPS") ? std::atoi(std::getenv("ARBOR_JOURNAL_FLIPS")) : 1000;
  for (int trial = 0; trial < trials; ++trial) {
    std::vector<char> b = clean;
    const auto at = static_cast<std::int64_t>(rng() % b.size());
    b[static_cast<size_t>(at)] = static_cast<char>(b[static_cast<size_t>(at)] ^ (1 + rng() % 255));
    writeBytes(copy, b);
    const EventLogContents c = readEventLog(copy);
    const int hit = eventAt(spans, at);
    SCOPED_TRACE("byte " + std::to_string(at) + " of event " + std::to_string(hit));
    ASSERT_EQ(channels(c), channelsWithout(n, hit));
    if (hit + 1 < n) {
      EXPECT_EQ(c.damaged_events, 1);
      ASSERT_EQ(c.damaged.size(), 1u);
      EXPECT_EQ(c.damaged[0].first, spans[static_cast<size_t>(hit)].first);
      EXPECT_EQ(c.damaged[0].second, spans[static_cast<size_t>(hit)].second);
      EXPECT_EQ(c.valid_bytes, c.file_bytes);
    } else {
      EXPECT_EQ(c.valid_bytes, spans[static_cast<size_t>(hit)].first);
    }
  }
  std::remove(path.c_str());
  std::remove(copy.c_str());
}

// A length field of 0x7FFFFFFF (or negative, or past the end) in any event: no allocation from
// it, that event skipped and counted, every other one read.
TEST(LcmJournalDamage, AnImpossibleLengthCostsOnlyItsEvent) {
  const int n = 12;
  const std::string path = tempPath("length.lcmlog");
  const std::string copy = tempPath("length.copy.lcmlog");
  const auto spans = writeLog(path, n);
  const std::vector<char> clean = readBytes(path);
  for (const int field : {20, 24}) {  // channel length, data length
    for (const std::uint32_t value : {0x7FFFFFFFu, 0xFFFFFFFFu, 0x80000000u, 0x10000u}) {
      for (int k = 0; k + 1 < n; ++k) {
        std::vector<char> b = clean;
        const auto at = static_cast<size_t>(spans[static_cast<size_t>(k)].first + field);
        for (int i = 0; i < 4; ++i) b[at + i] = static_cast<char>(value >> (24 - 8 * i));
        writeBytes(copy, b);
        const EventLogContents c = readEventLog(copy);
        SCOPED_TRACE("event " + std::to_string(k) + " field " + std::to_string(field));
        EXPECT_EQ(channels(c), channelsWithout(n, k));
        EXPECT_EQ(c.damaged_events, 1);
        ASSERT_EQ(c.damage_reasons.size(), 1u);  // the value read, named
        EXPECT_NE(c.damage_reasons[0].find(std::to_string(static_cast<std::int32_t>(value))),
                  std::string::npos)
            << c.damage_reasons[0];
      }
    }
  }
  std::remove(path.c_str());
  std::remove(copy.c_str());
}

// Junk after the last event (random bytes, zeros, the start of an event: what a torn write or a
// file extended without its data leaves) costs no event; a writer opened at valid_bytes cuts it
// and appends after the last event.
TEST(LcmJournalDamage, JunkAfterTheLastEventKeepsIt) {
  const int n = 8;
  const std::string path = tempPath("junk.lcmlog");
  const std::string copy = tempPath("junk.copy.lcmlog");
  const auto spans = writeLog(path, n);
  const std::vector<char> clean = readBytes(path);
  std::mt19937 rng(3);
  for (const int size : {1, 4, 27, 100, 3000}) {
    for (int kind = 0; kind < 3; ++kind) {
      std::vector<char> b = clean;
      const std::int64_t event_bytes = spans[1].second - spans[1].first;
      for (int i = 0; i < size; ++i) {
        const char random = static_cast<char>(rng());
        // kind 2: event 1 but its last byte (a write cut short), then zeros
        const char prefix =
            i + 1 < event_bytes ? clean[static_cast<size_t>(spans[1].first + i)] : '\0';
        b.push_back(kind == 0 ? random : kind == 1 ? '\0' : prefix);
      }
      writeBytes(copy, b);
      EventLogContents c = readEventLog(copy);
      SCOPED_TRACE(std::to_string(size) + " bytes of kind " + std::to_string(kind));
      ASSERT_EQ(channels(c), channelsWithout(n, -1));
      EXPECT_EQ(c.valid_bytes, static_cast<std::int64_t>(clean.size()));
      EXPECT_EQ(c.file_bytes - c.valid_bytes, size);
      // An event's start followed by zeros reads as a whole event whose checksum fails.
      EXPECT_LE(c.damaged_events, kind == 2 && size >= event_bytes ? 1 : 0);
      {
        EventLogWriter w(copy, c.valid_bytes);
        w.append("AFTER", 1, "xyz", 3);
      }
      c = readEventLog(copy);
      ASSERT_EQ(c.events.size(), static_cast<size_t>(n + 1));
      EXPECT_EQ(c.events.back().channel, "AFTER");
      EXPECT_EQ(c.valid_bytes, c.file_bytes);
    }
  }
  std::remove(path.c_str());
  std::remove(copy.c_str());
}

// A log cut at every length: the events wholly before the cut are read, nothing is damage, a
// cut inside an event is a torn tail.
TEST(LcmJournalDamage, ACutAnywhereCostsOnlyTheEventsItCuts) {
  const int n = 6;
  const std::string path = tempPath("cut.lcmlog");
  const std::string copy = tempPath("cut.copy.lcmlog");
  const auto spans = writeLog(path, n);
  const std::vector<char> clean = readBytes(path);
  for (size_t length = 0; length <= clean.size(); ++length) {
    writeBytes(copy, std::vector<char>(clean.begin(), clean.begin() + length));
    const EventLogContents c = readEventLog(copy);
    int whole = 0;
    while (whole < n &&
           spans[static_cast<size_t>(whole)].second <= static_cast<std::int64_t>(length))
      ++whole;
    ASSERT_EQ(c.events.size(), static_cast<size_t>(whole)) << length;
    EXPECT_EQ(c.damaged_events, 0);
    EXPECT_EQ(c.valid_bytes, whole == 0 ? 0 : spans[static_cast<size_t>(whole - 1)].second);
    EXPECT_EQ(c.torn_tail, c.valid_bytes < static_cast<std::int64_t>(length));
  }
  std::remove(path.c_str());
  std::remove(copy.c_str());
}

// The checksum rides in the event number, which liblcm's reader (lcm-logplayer's) ignores: it
// still reads every event of a checksummed log, channel, timestamp and data.
TEST(LcmJournalDamage, LiblcmStillReadsAChecksummedLog) {
  const int n = 7;
  const std::string path = tempPath("liblcm.lcmlog");
  writeLog(path, n);
  const EventLogContents ours = readEventLog(path);
  lcm_eventlog_t* log = lcm_eventlog_create(path.c_str(), "r");
  ASSERT_NE(log, nullptr);
  int k = 0;
  while (lcm_eventlog_event_t* e = lcm_eventlog_read_next_event(log)) {
    ASSERT_LT(k, n);
    const LogEvent& o = ours.events[static_cast<size_t>(k)];
    EXPECT_EQ(std::string(e->channel, static_cast<size_t>(e->channellen)), o.channel);
    EXPECT_EQ(e->timestamp, o.timestamp);
    EXPECT_EQ(static_cast<std::uint64_t>(e->eventnum) >> 32, kEventChecksumTag);
    const auto* data = static_cast<const std::uint8_t*>(e->data);
    EXPECT_EQ(std::vector<std::uint8_t>(data, data + e->datalen), o.data);
    lcm_eventlog_free_event(e);
    ++k;
  }
  lcm_eventlog_destroy(log);
  EXPECT_EQ(k, n);
  std::remove(path.c_str());
}

// A log written by liblcm (event numbers 0, 1, 2, …: no checksum) is read, its events counted
// unchecked; events appended to it carry checksums, and once one has been read an event without
// one is damage (its tag zeroed here), not an old event.
TEST(LcmJournalDamage, ALogFromBeforeChecksumsIsReadUncheckedUpToItsFirstChecksum) {
  const std::string path = tempPath("legacy.lcmlog");
  {
    lcm_eventlog_t* log = lcm_eventlog_create(path.c_str(), "w");
    ASSERT_NE(log, nullptr);
    for (int k = 0; k < 5; ++k) {
      std::string channel = "OLD" + std::to_string(k);
      std::string data(30, static_cast<char>('A' + k));
      lcm_eventlog_event_t e{};
      e.timestamp = 500 + k;
      e.channellen = static_cast<std::int32_t>(channel.size());
      e.datalen = static_cast<std::int32_t>(data.size());
      e.channel = channel.data();
      e.data = data.data();
      ASSERT_EQ(lcm_eventlog_write_event(log, &e), 0);
    }
    lcm_eventlog_destroy(log);
  }
  EventLogContents c = readEventLog(path);
  ASSERT_EQ(c.events.size(), 5u);
  EXPECT_EQ(c.unchecked_events, 5);
  EXPECT_FALSE(c.events[2].checked);
  EXPECT_EQ(c.events[2].timestamp, 502);
  {
    EventLogWriter w(path, c.valid_bytes);
    for (int k = 0; k < 3; ++k) w.append("NEW" + std::to_string(k), 9, "payload", 7);
  }
  c = readEventLog(path);
  ASSERT_EQ(c.events.size(), 8u);
  EXPECT_EQ(c.unchecked_events, 5);
  EXPECT_TRUE(c.events[5].checked);
  EXPECT_EQ(c.damaged_events, 0);
  // The tag of NEW1 zeroed: it now looks like an old event, after a checked one: damage.
  std::vector<char> b = readBytes(path);
  const auto tag_at = static_cast<size_t>(c.events[6].offset + 4);
  for (int i = 0; i < 4; ++i) b[tag_at + i] = 0;
  writeBytes(path, b);
  c = readEventLog(path);
  ASSERT_EQ(c.events.size(), 7u);
  EXPECT_EQ(c.events[6].channel, "NEW2");
  EXPECT_EQ(c.damaged_events, 1);
  std::remove(path.c_str());
}

}  // namespace
}  // namespace arbor
