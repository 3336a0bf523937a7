// LCM's udpm wire format, checked before anything parses it, and the reassembly of fragmented
// messages in a bounded table: what `arbor serve` runs instead of liblcm's udpm receive path
// (whose fragment check wraps around 2^32 and writes out of bounds: issue 56). No sockets here:
// one datagram in, at most one complete message out (tools/serve/udpm_receiver.h reads them).
//
// The format (liblcm 1.3's lcm_udpm.c and udpm_util.h, all integers big-endian):
// - LC02, a whole message: magic 0x4c433032, seqno (4), the channel name and its NUL, the data.
// - LC03, one fragment: magic 0x4c433033, seqno (4), msg_size (4, the data's size, channel not
//   included), fragment_offset (4, into the data), fragment_no (2), fragments_in_msg (2); then
//   fragment 0 carries the channel name and its NUL before its data, the others only data.
// A sender has one message in flight at a time: fragments are told apart by the source address
// and port, and a fragment of another seqno from that source drops the message it was building.
//
// A datagram is refused (counted by reason, never parsed further) when it is shorter than its
// header ("short"), has neither magic ("magic"), has no NUL-terminated channel name of 1 to 63
// bytes inside it ("channel"), claims a message of 0 bytes or over `max_message_bytes`
// ("message size"), a fragment number not below its count or a count of 0 ("fragment number"),
// a fragment that is empty, starts fragment 0 elsewhere than at 0 or reaches past msg_size
// (64-bit sums: "fragment range"), that overlaps bytes or repeats a fragment number already
// received ("fragment overlap"), that disagrees with its message's size or count
// ("fragment inconsistent"), or completes the bytes with another number of fragments than
// announced ("fragment count"). A message on a channel `wants` refuses is skipped (LC03: its
// fragment 0 starts no entry and its later fragments find none), not counted as refused.
//
// Memory: at most `max_partial_messages` messages in reassembly, their buffers (data plus a bit a
// byte of coverage) together at most `max_partial_bytes`; a new message that does not fit evicts
// the least recently touched ones, counted as dropped. One datagram buffer and one completed
// message are kept besides.
#pragma once

#include <cstddef>
#include <cstdint>
#include <functional>
#include <map>
#include <string>
#include <vector>

namespace arbor::serve {

inline constexpr std::uint32_t kLcmMagicShort = 0x4c433032;  ///< "LC02"
inline constexpr std::uint32_t kLcmMagicLong = 0x4c433033;   ///< "LC03"
inline constexpr std::size_t kLcmShortHeaderBytes = 8;
inline constexpr std::size_t kLcmLongHeaderBytes = 20;
inline constexpr std::size_t kLcmMaxChannelBytes = 63;  ///< LCM_MAX_CHANNEL_NAME_LENGTH

struct DatagramLimits {
  std::uint32_t max_message_bytes = 1u << 20;  ///< a reassembled message (LC03 msg_size)
  std::size_t max_partial_messages = 16;       ///< messages in reassembly at once
  std::size_t max_partial_bytes = 4u << 20;    ///< their buffers together
};

/// What one datagram gave.
struct DatagramOutcome {
  std::string refused;  ///< "": not refused; else the reason (see above)
  std::string detail;   ///< with `refused`: the numbers that made it so
  bool complete = false;
  std::string channel;                 ///< with `complete`
  const std::uint8_t* data = nullptr;  ///< with `complete`: valid until the next datagram
  std::size_t size = 0;
};

class LcmDatagramAssembler {
 public:
  using Wants = std::function<bool(const std::string& channel)>;

  LcmDatagramAssembler(DatagramLimits limits, Wants wants);

  /// One datagram of `size` bytes from `source` (address and port, any unique number).
  DatagramOutcome add(std::uint64_t source, const std::uint8_t* bytes, std::size_t size);

  std::size_t partialMessages() const { return partials_.size(); }
  std::size_t partialBytes() const { return partial_bytes_; }
  /// Messages whose fragments stopped coming (replaced by a newer seqno from the same source,
  /// evicted for room, or dropped with a refused fragment).
  std::int64_t droppedPartials() const { return dropped_partials_; }

 private:
  struct Partial {
    std::uint32_t seqno = 0, size = 0;
    std::uint16_t count = 0;
    std::string channel;
    std::vector<std::uint8_t> data;
    std::vector<std::uint64_t> covered;  ///< a bit a byte of data
    std::vector<std::uint64_t> numbers;  ///< a bit a fragment number
    std::uint32_t fragments = 0;         ///< received
    std::uint64_t covered_bytes = 0;
    std::uint64_t touched = 0;  ///< the datagram count when last added to
    std::size_t bytes() const { return data.size() + 8 * (covered.size() + numbers.size()); }
  };

  DatagramOutcome shortMessage(const std::uint8_t* bytes, std::size_t size);
  DatagramOutcome fragment(std::uint64_t source, const std::uint8_t* bytes, std::size_t size);
  /// Starts a message for fragment 0 (evicting for room); null if it cannot fit.
  Partial* start(std::uint64_t source, std::uint32_t seqno, std::uint32_t msg_size,
                 std::uint16_t count, const std::string& channel);
  void drop(std::uint64_t source);

  DatagramLimits limits_;
  Wants wants_;
  std::map<std::uint64_t, Partial> partials_;  ///< by source
  std::size_t partial_bytes_ = 0;
  std::int64_t dropped_partials_ = 0;
  std::uint64_t datagrams_ = 0;
  std::vector<std::uint8_t> completed_;
};

/// The channel name at `bytes` (at most `size` bytes): "" when there is no NUL within the first
/// kLcmMaxChannelBytes + 1 bytes or the name is empty.
std::string lcmChannelAt(const std::uint8_t* bytes, std::size_t size);

}  // namespace arbor::serve
