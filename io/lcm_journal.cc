#include "arbor/io/lcm_journal.h"

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <stdexcept>
#include <vector>

#include <stdio_ext.h>

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <lcm/eventlog.h>

namespace arbor {
namespace {

std::int64_t steadyMicros() {
  return std::chrono::duration_cast<std::chrono::microseconds>(
             std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

// The offset of the first event sync word (0xEDA1DA01, big-endian) at or after `from` and
// before `end`, or −1.
std::int64_t nextSyncWord(FILE* f, std::int64_t from, std::int64_t end) {
  static constexpr unsigned char kSync[4] = {0xED, 0xA1, 0xDA, 0x01};
  if (from >= end || std::fseek(f, from, SEEK_SET) != 0) return -1;
  std::vector<unsigned char> buffer(1 << 16);
  std::int64_t base = from;  // file offset of buffer[0]
  size_t kept = 0;           // bytes carried over from the previous chunk
  for (;;) {
    const size_t got = std::fread(buffer.data() + kept, 1, buffer.size() - kept, f);
    const size_t n = kept + got;
    for (size_t k = 0; k + 4 <= n; ++k)
      if (std::memcmp(buffer.data() + k, kSync, 4) == 0) {
        const std::int64_t at = base + static_cast<std::int64_t>(k);
        return at < end ? at : -1;
      }
    if (got == 0) return -1;
    kept = std::min<size_t>(3, n);  // a sync word may straddle two chunks
    std::memmove(buffer.data(), buffer.data() + n - kept, kept);
    base += static_cast<std::int64_t>(n - kept);
  }
}

std::string systemError(const std::string& what, const std::string& path) {
  return what + " " + path + ": " + std::strerror(errno);
}

}  // namespace

EventLogContents readEventLog(const std::string& path) {
  EventLogContents out;
  struct stat st;
  if (::stat(path.c_str(), &st) != 0) {
    if (errno == ENOENT) return out;
    throw std::runtime_error(systemError("readEventLog: cannot stat", path));
  }
  out.file_bytes = st.st_size;
  lcm_eventlog_t* log = lcm_eventlog_create(path.c_str(), "r");
  if (log == nullptr) throw std::runtime_error(systemError("readEventLog: cannot open", path));
  // Where the reading stopped short of the end (damage, or a torn tail), it resumes at the next
  // sync word; the stretch becomes `damaged` once a complete event follows it.
  std::int64_t damage_start = -1;
  std::int64_t resume = 0;
  for (;;) {
    while (lcm_eventlog_event_t* e = lcm_eventlog_read_next_event(log)) {
      LogEvent event;
      event.channel.assign(e->channel, static_cast<size_t>(e->channellen));
      event.timestamp = e->timestamp;
      const auto* bytes = static_cast<const std::uint8_t*>(e->data);
      event.data.assign(bytes, bytes + e->datalen);
      lcm_eventlog_free_event(e);
      out.events.push_back(std::move(event));
      if (damage_start >= 0) {
        out.damaged.emplace_back(damage_start, resume);
        damage_start = -1;
      }
      out.valid_bytes = ftell(log->f);
    }
    if (out.valid_bytes >= out.file_bytes) break;
    if (damage_start < 0) {
      damage_start = out.valid_bytes;
      resume = out.valid_bytes;
    }
    resume = nextSyncWord(log->f, resume + 1, out.file_bytes);
    if (resume < 0 || std::fseek(log->f, resume, SEEK_SET) != 0) break;  // a torn tail
    std::clearerr(log->f);
  }
  lcm_eventlog_destroy(log);
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
  log_ = lcm_eventlog_create(path.c_str(), "a");
  if (log_ == nullptr) throw std::runtime_error(systemError("EventLogWriter: cannot open", path));
  struct stat st;
  if (::fstat(fileno(log_->f), &st) != 0) {
    const std::string error = systemError("EventLogWriter: cannot stat", path);
    lcm_eventlog_destroy(log_);
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
  if (log_ == nullptr) return;
  fflush(log_->f);
  if (dirty_) fsync(fileno(log_->f));
  lcm_eventlog_destroy(log_);
}

void EventLogWriter::append(const std::string& channel, std::int64_t timestamp, const void* data,
                            int size, EventClass kind) {
  std::lock_guard<std::mutex> lock(mutex_);
  // An event on disk: sync word, event number, timestamp, channel and data lengths, channel,
  // data (lcm_eventlog_write_event).
  const std::int64_t event_bytes =
      4 + 8 + 8 + 4 + 4 + static_cast<std::int64_t>(channel.size()) + size;
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
  lcm_eventlog_event_t e;
  std::memset(&e, 0, sizeof e);
  e.timestamp = timestamp;
  e.channellen = static_cast<std::int32_t>(channel.size());
  e.datalen = size;
  e.channel = const_cast<char*>(channel.c_str());
  e.data = const_cast<void*>(data);
  if (lcm_eventlog_write_event(log_, &e) != 0 || fflush(log_->f) != 0) {
    rollBack();  // keeps errno
    return false;
  }
  return true;
}

void EventLogWriter::rollBack() {
  // What stdio still holds of the failed event must never reach the file later.
  __fpurge(log_->f);
  std::clearerr(log_->f);
  const int saved = errno;
  if (::ftruncate(fileno(log_->f), bytes_) != 0) {
    // The torn event stays; events after it are found again at their sync words (damage).
    struct stat st;
    if (::fstat(fileno(log_->f), &st) == 0) bytes_ = st.st_size;
  }
  errno = saved;
}

void EventLogWriter::syncLocked() {
  if (!dirty_) return;
  if (fsync(fileno(log_->f)) != 0) {
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
