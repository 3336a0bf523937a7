#include "arbor_slam/io/lcm_journal.h"

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <stdexcept>
#include <vector>

#include <stdio_ext.h>

#include <fcntl.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#include <zlib.h>

namespace arbor {
namespace {

std::int64_t steadyMicros() {
  return std::chrono::duration_cast<std::chrono::microseconds>(
             std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

constexpr unsigned char kSyncWord[4] = {0xED, 0xA1, 0xDA, 0x01};
/// sync word, event number, timestamp, channel length, data length
constexpr std::int64_t kHeaderBytes = 4 + 8 + 8 + 4 + 4;
/// Longer channel names are not ours (LCM's own limit is 63).
constexpr std::int64_t kMaxChannelBytes = 255;

std::uint64_t bigEndian(const std::uint8_t* p, int bytes) {
  std::uint64_t v = 0;
  for (int k = 0; k < bytes; ++k) v = (v << 8) | p[k];
  return v;
}

void putBigEndian(std::uint64_t v, int bytes, std::uint8_t* p) {
  for (int k = bytes - 1; k >= 0; --k, v >>= 8) p[k] = static_cast<std::uint8_t>(v);
}

/// zlib's crc32 of `size` bytes (an event is < 4 GiB: its lengths are 32-bit).
std::uint32_t checksum(std::uint32_t crc, const void* data, std::int64_t size) {
  if (size == 0) return crc;  // crc32(crc, NULL, 0) would be the initial value
  return static_cast<std::uint32_t>(
      ::crc32(crc, static_cast<const Bytef*>(data), static_cast<uInt>(size)));
}

/// What starts at an offset of the log.
struct Parsed {
  enum Kind {
    kChecked,     ///< a complete event whose checksum verifies
    kUnchecked,   ///< a complete event written before checksums (allowed: none seen yet)
    kIncomplete,  ///< the start of an event the file ends inside (a torn write)
    kNotAnEvent,  ///< anything else: a bad sync word, tag, length or checksum
  };
  Kind kind = kNotAnEvent;
  std::int64_t end = 0;  ///< just after the event (kChecked, kUnchecked)
};

std::string hex(std::uint64_t v) {
  char text[24];
  std::snprintf(text, sizeof text, "0x%llx", static_cast<unsigned long long>(v));
  return text;
}

/// Validates the event at `at` in the `n` bytes of `b`: every length against the file before
/// it is used, then the checksum. `why` (if given) says what failed, with the value read.
Parsed parseAt(const std::uint8_t* b, std::int64_t n, std::int64_t at, bool unchecked_allowed,
               std::string* why = nullptr) {
  Parsed p;
  const auto fail = [&](Parsed::Kind kind, const std::string& what) {
    p.kind = kind;
    if (why != nullptr) *why = what;
    return p;
  };
  const std::int64_t left = n - at;
  const auto head = static_cast<size_t>(std::min<std::int64_t>(4, left));
  if (std::memcmp(b + at, kSyncWord, head) != 0)
    return fail(Parsed::kNotAnEvent,
                "no sync word (reads " + hex(bigEndian(b + at, static_cast<int>(head))) + ")");
  if (left < kHeaderBytes)
    return fail(Parsed::kIncomplete, "an event header cut short after " + std::to_string(left) +
                                         " bytes by the end of the file");
  const std::uint8_t* h = b + at;
  const std::uint64_t number = bigEndian(h + 4, 8);
  const auto tag = static_cast<std::uint32_t>(number >> 32);
  const auto channel_bytes = static_cast<std::int32_t>(bigEndian(h + 20, 4));
  const auto data_bytes = static_cast<std::int32_t>(bigEndian(h + 24, 4));
  const bool tagged = tag == kEventChecksumTag;
  if (!tagged && !(tag == 0 && unchecked_allowed))
    return fail(Parsed::kNotAnEvent, "event number " + hex(number) + " without the checksum tag");
  if (channel_bytes < 1 || channel_bytes > kMaxChannelBytes)
    return fail(Parsed::kNotAnEvent, "channel length " + std::to_string(channel_bytes));
  if (data_bytes < 0) return fail(Parsed::kNotAnEvent, "data length " + std::to_string(data_bytes));
  const std::int64_t end = at + kHeaderBytes + channel_bytes + data_bytes;
  if (end > n)
    return fail(Parsed::kIncomplete, "data length " + std::to_string(data_bytes) +
                                         " runs past the end of the file by " +
                                         std::to_string(end - n) + " bytes");
  if (tagged) {
    const std::uint32_t crc = checksum(0, h + 12, end - at - 12);
    if (crc != static_cast<std::uint32_t>(number))
      return fail(Parsed::kNotAnEvent, "checksum " + hex(static_cast<std::uint32_t>(number)) +
                                           ", the bytes give " + hex(crc));
  }
  p.kind = tagged ? Parsed::kChecked : Parsed::kUnchecked;
  p.end = end;
  return p;
}

/// The offset of the first sync word at or after `from` in the `n` bytes of `b`, or n.
std::int64_t nextSyncWord(const std::uint8_t* b, std::int64_t n, std::int64_t from) {
  for (std::int64_t k = from; k + 4 <= n; ++k) {
    const void* hit = std::memchr(b + k, kSyncWord[0], static_cast<size_t>(n - 3 - k));
    if (hit == nullptr) return n;
    k = static_cast<const std::uint8_t*>(hit) - b;
    if (std::memcmp(b + k, kSyncWord, 4) == 0) return k;
  }
  return n;
}

/// The event starts (sync words) in [first, end).
std::int64_t syncWordsIn(const std::uint8_t* b, std::int64_t first, std::int64_t end) {
  std::int64_t count = 0;
  for (std::int64_t k = nextSyncWord(b, end, first); k < end; k = nextSyncWord(b, end, k + 1))
    ++count;
  return count;
}

std::string systemError(const std::string& what, const std::string& path) {
  return what + " " + path + ": " + std::strerror(errno);
}

/// The file's bytes, mapped read-only for the time of the reading.
class MappedFile {
 public:
  MappedFile(int fd, std::int64_t size) : size_(size) {
    if (size_ == 0) return;
    void* p = ::mmap(nullptr, static_cast<size_t>(size_), PROT_READ, MAP_PRIVATE, fd, 0);
    if (p != MAP_FAILED) data_ = static_cast<const std::uint8_t*>(p);
  }
  ~MappedFile() {
    if (data_ != nullptr) ::munmap(const_cast<std::uint8_t*>(data_), static_cast<size_t>(size_));
  }
  MappedFile(const MappedFile&) = delete;
  MappedFile& operator=(const MappedFile&) = delete;
  bool ok() const { return size_ == 0 || data_ != nullptr; }
  const std::uint8_t* data() const { return data_; }

 private:
  const std::uint8_t* data_ = nullptr;
  std::int64_t size_ = 0;
};

}  // namespace

EventLogContents readEventLog(const std::string& path) {
  EventLogContents out;
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) {
    if (errno == ENOENT) return out;
    throw std::runtime_error(systemError("readEventLog: cannot open", path));
  }
  struct stat st;
  if (::fstat(fd, &st) != 0) {
    const std::string error = systemError("readEventLog: cannot stat", path);
    ::close(fd);
    throw std::runtime_error(error);
  }
  const std::int64_t n = st.st_size;
  out.file_bytes = n;
  const MappedFile file(fd, n);
  ::close(fd);
  if (!file.ok()) throw std::runtime_error(systemError("readEventLog: cannot map", path));
  const std::uint8_t* b = file.data();
  // Where no event starts (damage, or the tail), the reading resumes at the next sync word at
  // which one does; the stretch becomes `damaged` once an event follows it.
  bool checked_seen = false;
  std::int64_t damage_start = -1;
  std::string why;  // what the first offset of the damaged stretch failed
  std::int64_t at = 0;
  while (at < n) {
    const Parsed p = parseAt(b, n, at, !checked_seen);
    if (p.kind != Parsed::kChecked && p.kind != Parsed::kUnchecked) {
      if (damage_start < 0) {
        damage_start = at;
        parseAt(b, n, at, !checked_seen, &why);
      }
      at = nextSyncWord(b, n, at + 1);
      continue;
    }
    if (damage_start >= 0) {
      out.damaged.emplace_back(damage_start, at);
      out.damage_reasons.push_back(why);
      out.damaged_events += std::max<std::int64_t>(1, syncWordsIn(b, damage_start, at));
      damage_start = -1;
    }
    const std::uint8_t* h = b + at;
    const auto channel_bytes = static_cast<size_t>(bigEndian(h + 20, 4));
    LogEvent event;
    event.offset = at;
    event.checked = p.kind == Parsed::kChecked;
    event.timestamp = static_cast<std::int64_t>(bigEndian(h + 12, 8));
    event.channel.assign(reinterpret_cast<const char*>(h + kHeaderBytes), channel_bytes);
    event.data.assign(h + kHeaderBytes + channel_bytes, b + p.end);
    out.events.push_back(std::move(event));
    if (p.kind == Parsed::kChecked) {
      checked_seen = true;
    } else {
      ++out.unchecked_events;
    }
    at = p.end;
    out.valid_bytes = at;
  }
  // The tail: every event start in it is damage, but for a last write cut short.
  if (out.valid_bytes < n) parseAt(b, n, out.valid_bytes, !checked_seen, &out.tail_reason);
  for (std::int64_t k = out.valid_bytes; k < n; k = nextSyncWord(b, n, k + 1)) {
    if (parseAt(b, n, k, !checked_seen).kind == Parsed::kIncomplete) {
      out.torn_tail = true;
    } else if (k + 4 <= n && std::memcmp(b + k, kSyncWord, 4) == 0) {
      ++out.damaged_events;
    }
  }
  return out;
}

EventLogWriter::EventLogWriter(const std::string& path, std::int64_t valid_bytes,
                               EventLogWriterOptions options)
    : path_(path), options_(options) {
  if (valid_bytes >= 0) {
    struct stat st;
    if (::stat(path.c_str(), &st) == 0 && st.st_size > valid_bytes &&
        ::truncate(path.c_str(), valid_bytes) != 0) {
      throw std::runtime_error(systemError("EventLogWriter: cannot truncate", path));
    }
  }
  file_ = std::fopen(path.c_str(), "abe");
  if (file_ == nullptr) throw std::runtime_error(systemError("EventLogWriter: cannot open", path));
  struct stat st;
  if (::fstat(fileno(file_), &st) != 0) {
    const std::string error = systemError("EventLogWriter: cannot stat", path);
    std::fclose(file_);
    throw std::runtime_error(error);
  }
  bytes_ = st.st_size;
  last_sync_us_ = steadyMicros();
  reserve_path_ = path + ".reserve";
  reserve_held_ = options_.reserve_bytes <= 0 || makeReserve();
}

bool EventLogWriter::makeReserve() {
  const int fd = ::open(reserve_path_.c_str(), O_WRONLY | O_CREAT | O_CLOEXEC | O_NOFOLLOW, 0644);
  if (fd < 0) return false;
  // Blocks really allocated (not a sparse file), or the room is not held.
  const bool ok = ::posix_fallocate(fd, 0, options_.reserve_bytes) == 0 && ::fsync(fd) == 0;
  ::close(fd);
  if (!ok) ::unlink(reserve_path_.c_str());
  return ok;
}

EventLogWriter::~EventLogWriter() {
  std::lock_guard<std::mutex> lock(mutex_);
  if (file_ == nullptr) return;
  std::fflush(file_);
  if (dirty_) ::fsync(fileno(file_));
  std::fclose(file_);
}

void EventLogWriter::append(const std::string& channel, std::int64_t timestamp, const void* data,
                            int size, EventClass kind) {
  std::lock_guard<std::mutex> lock(mutex_);
  // An event on disk: sync word, event number (tag and checksum), timestamp, channel and data
  // lengths, channel, data.
  const std::int64_t event_bytes = kHeaderBytes + static_cast<std::int64_t>(channel.size()) + size;
  const bool measurement = kind == EventClass::kMeasurement;
  const std::int64_t limit =
      options_.max_bytes - (measurement ? std::max<std::int64_t>(0, options_.reserve_bytes) : 0);
  if (options_.max_bytes > 0 && bytes_ + event_bytes > limit) {
    ++failures_;
    throw std::runtime_error(
        "EventLogWriter: cannot write " + path_ + ": the journal is full (" +
        std::to_string(bytes_) + " of at most " + std::to_string(options_.max_bytes) + " bytes" +
        (measurement ? ", " + std::to_string(options_.reserve_bytes) + " of them kept for marks"
                     : "") +
        "; the event needs " + std::to_string(event_bytes) + ")");
  }
  if (measurement && !reserve_held_ && !(reserve_held_ = makeReserve())) {
    ++failures_;
    throw std::runtime_error(
        "EventLogWriter: cannot write " + path_ + ": the disk is full (no room for the " +
        std::to_string(options_.reserve_bytes) + " bytes kept for marks beside the journal)");
  }
  if (!writeEvent(channel, timestamp, data, size)) {
    // A record may use the reserve: free it and try once more.
    const bool retry = !measurement && options_.reserve_bytes > 0 && reserve_held_ &&
                       (errno == ENOSPC || errno == EDQUOT);
    if (retry) {
      ::unlink(reserve_path_.c_str());
      reserve_held_ = false;
    }
    if (!retry || !writeEvent(channel, timestamp, data, size)) {
      ++failures_;
      throw std::runtime_error(systemError("EventLogWriter: cannot write", path_));
    }
  }
  bytes_ += event_bytes;
  ++written_;
  dirty_ = true;
  if (options_.fsync_interval_ms == 0 ||
      (options_.fsync_interval_ms > 0 &&
       steadyMicros() - last_sync_us_ >= 1000LL * options_.fsync_interval_ms)) {
    syncLocked();
  }
}

bool EventLogWriter::writeEvent(const std::string& channel, std::int64_t timestamp,
                                const void* data, int size) {
  if (channel.empty() || static_cast<std::int64_t>(channel.size()) > kMaxChannelBytes || size < 0) {
    errno = EINVAL;  // the reader would take it for damage
    return false;
  }
  std::uint8_t header[kHeaderBytes];
  std::memcpy(header, kSyncWord, 4);
  putBigEndian(static_cast<std::uint64_t>(timestamp), 8, header + 12);
  putBigEndian(channel.size(), 4, header + 20);
  putBigEndian(static_cast<std::uint64_t>(size), 4, header + 24);
  std::uint32_t crc = checksum(0, header + 12, kHeaderBytes - 12);
  crc = checksum(crc, channel.data(), static_cast<std::int64_t>(channel.size()));
  crc = checksum(crc, data, size);
  putBigEndian((static_cast<std::uint64_t>(kEventChecksumTag) << 32) | crc, 8, header + 4);
  if (std::fwrite(header, 1, sizeof header, file_) != sizeof header ||
      std::fwrite(channel.data(), 1, channel.size(), file_) != channel.size() ||
      std::fwrite(data, 1, static_cast<size_t>(size), file_) != static_cast<size_t>(size) ||
      std::fflush(file_) != 0) {
    rollBack();  // keeps errno
    return false;
  }
  return true;
}

void EventLogWriter::rollBack() {
  // What stdio still holds of the failed event must never reach the file later.
  __fpurge(file_);
  std::clearerr(file_);
  const int saved = errno;
  if (::ftruncate(fileno(file_), bytes_) != 0) {
    // The torn event stays; events after it are found again at their sync words (damage).
    struct stat st;
    if (::fstat(fileno(file_), &st) == 0) bytes_ = st.st_size;
  }
  errno = saved;
}

void EventLogWriter::syncLocked() {
  if (!dirty_) return;
  if (fsync(fileno(file_)) != 0) {
    throw std::runtime_error(systemError("EventLogWriter: cannot fsync", path_));
  }
  dirty_ = false;
  last_sync_us_ = steadyMicros();
}

void EventLogWriter::sync() {
  std::lock_guard<std::mutex> lock(mutex_);
  syncLocked();
}

void EventLogWriter::syncIfDue() {
  std::lock_guard<std::mutex> lock(mutex_);
  if (options_.fsync_interval_ms > 0 &&
      steadyMicros() - last_sync_us_ >= 1000LL * options_.fsync_interval_ms) {
    syncLocked();
  }
}

std::int64_t EventLogWriter::bytes() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return bytes_;
}

std::int64_t EventLogWriter::failures() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return failures_;
}

std::int64_t EventLogWriter::eventsWritten() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return written_;
}

}  // namespace arbor
