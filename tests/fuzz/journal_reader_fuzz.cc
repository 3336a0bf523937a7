// The journal's reader (io/lcm_journal.h, readEventLog) on an untrusted file: the input is the
// whole file. What it finds must hold together (events in order inside the valid bytes, damaged
// stretches before them, a reason for each), and every event's data goes through the decoders,
// as the replay of `arbor serve` hands it to them. Never a crash, a hang or an allocation from
// an unchecked length.
#include <cstddef>
#include <cstdint>
#include <string>

#include <sys/mman.h>
#include <unistd.h>

#include "arbor_slam/io/lcm_journal.h"
#include "arbor_slam/tests/fuzz/fuzz_checks.h"

namespace {

// The file: a memfd (no disk write per input: rewriting a file on ext4 flushes it at each
// close), opened by readEventLog through its /proc/self/fd path.
int scratchFd() {
  static const int fd = ::memfd_create("arbor-fuzz-journal", MFD_CLOEXEC);
  arbor::fuzz::require(fd >= 0, "memfd_create failed");
  return fd;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace arbor;
  const int fd = scratchFd();
  fuzz::require(::ftruncate(fd, 0) == 0, "ftruncate failed");
  std::size_t done = 0;
  while (done < size) {
    const ssize_t n = ::pwrite(fd, data + done, size - done, static_cast<off_t>(done));
    fuzz::require(n > 0, "pwrite failed");
    done += static_cast<std::size_t>(n);
  }
  const std::string path = "/proc/self/fd/" + std::to_string(fd);
  const EventLogContents log = readEventLog(path);
  const auto n = static_cast<std::int64_t>(size);
  fuzz::require(log.file_bytes == n, "file_bytes");
  fuzz::require(log.valid_bytes >= 0 && log.valid_bytes <= n, "valid_bytes");
  fuzz::require(log.damaged.size() == log.damage_reasons.size(),
                "a damaged stretch without reason");
  fuzz::require(log.valid_bytes == n || !log.tail_reason.empty(), "a tail without reason");
  std::int64_t previous = -1;
  for (const LogEvent& e : log.events) {
    fuzz::require(e.offset > previous && e.offset < log.valid_bytes, "event offsets");
    fuzz::require(e.offset + static_cast<std::int64_t>(e.data.size()) <= log.valid_bytes,
                  "an event past the valid bytes");
    previous = e.offset;
  }
  for (const auto& [first, last] : log.damaged) {
    fuzz::require(0 <= first && first < last && last <= log.valid_bytes, "a damaged stretch");
  }
  fuzz::require(log.damaged_events >= static_cast<std::int64_t>(log.damaged.size()),
                "damaged_events");
  for (const LogEvent& e : log.events) fuzz::decodeAll(e.data.data(), e.data.size());
  return 0;
}
