// serve's udpm receive path (tools/serve/lcm_datagram.h): LCM's wire format checked, fragments
// reassembled in a bounded table, before anything parses the bytes. The input is a sequence of
// datagrams, each [source: 1 byte][length: 2 bytes, big-endian][that many bytes] (the last one
// takes what is left), from 4 sources; a complete message goes through every decoder, as serve
// hands it to the one of its channel. The memory bounds must hold after every datagram, and a
// refusal must name its reason.
#include <cstddef>
#include <cstdint>
#include <string>

#include "arbor_slam/tests/fuzz/fuzz_checks.h"
#include "arbor_slam/tools/serve/lcm_datagram.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace arbor;
  serve::DatagramLimits limits;
  limits.max_message_bytes = 1u << 16;  // small bounds, so that eviction is met
  limits.max_partial_messages = 3;
  limits.max_partial_bytes = 1u << 17;
  serve::LcmDatagramAssembler assembler(
      limits, [](const std::string& channel) { return channel != "SKIPPED"; });
  std::size_t at = 0;
  while (at + 3 <= size) {
    const std::uint64_t source = data[at] & 3u;
    std::size_t length = (std::size_t{data[at + 1]} << 8) | data[at + 2];
    at += 3;
    if (length > size - at) length = size - at;
    const serve::DatagramOutcome out = assembler.add(source, data + at, length);
    at += length;
    fuzz::require(assembler.partialMessages() <= limits.max_partial_messages, "partial messages");
    fuzz::require(assembler.partialBytes() <= limits.max_partial_bytes, "partial bytes");
    if (!out.refused.empty()) {
      fuzz::require(!out.complete, "a refused datagram completed a message");
      fuzz::require(!out.detail.empty(), "a refusal without detail", out.refused);
      continue;
    }
    if (!out.complete) continue;
    fuzz::require(!out.channel.empty() && out.channel.size() <= serve::kLcmMaxChannelBytes,
                  "a message on a bad channel name", out.channel);
    fuzz::require(out.channel != "SKIPPED", "a message on a channel not wanted");
    fuzz::require(out.size <= limits.max_message_bytes, "message size", std::to_string(out.size));
    fuzz::decodeAll(out.data, out.size);
  }
  return 0;
}
