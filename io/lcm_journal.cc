#include "io/lcm_journal.h"

#include <cerrno>
#include <chrono>
#include <cstring>
#include <stdexcept>

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
  while (lcm_eventlog_event_t* e = lcm_eventlog_read_next_event(log)) {
    LogEvent event;
    event.channel.assign(e->channel, static_cast<size_t>(e->channellen));
    event.timestamp = e->timestamp;
    const auto* bytes = static_cast<const std::uint8_t*>(e->data);
    event.data.assign(bytes, bytes + e->datalen);
    lcm_eventlog_free_event(e);
    out.events.push_back(std::move(event));
    out.valid_bytes = ftell(log->f);
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
  last_sync_us_ = steadyMicros();
}

EventLogWriter::~EventLogWriter() {
  std::lock_guard<std::mutex> lock(mutex_);
  if (log_ == nullptr) return;
  fflush(log_->f);
  if (dirty_) fsync(fileno(log_->f));
  lcm_eventlog_destroy(log_);
}

void EventLogWriter::append(const std::string& channel, std::int64_t timestamp, const void* data,
                            int size) {
  std::lock_guard<std::mutex> lock(mutex_);
  lcm_eventlog_event_t e;
  std::memset(&e, 0, sizeof e);
  e.timestamp = timestamp;
  e.channellen = static_cast<std::int32_t>(channel.size());
  e.datalen = size;
  e.channel = const_cast<char*>(channel.c_str());
  e.data = const_cast<void*>(data);
  if (lcm_eventlog_write_event(log_, &e) != 0 || fflush(log_->f) != 0) {
    throw std::runtime_error(systemError("EventLogWriter: cannot write", path_));
  }
  ++written_;
  dirty_ = true;
  if (options_.fsync_interval_ms == 0 ||
      (options_.fsync_interval_ms > 0 &&
       steadyMicros() - last_sync_us_ >= 1000LL * options_.fsync_interval_ms)) {
    syncLocked();
  }
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

std::int64_t EventLogWriter::eventsWritten() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return written_;
}

}  // namespace arbor
