// LCM udpm datagrams for tests: a message as liblcm 1.3's lcm_udpm_publish puts it on the wire
// (LC02 whole, or LC03 fragments with the channel in fragment 0), the 544-byte fragment of
// issue 56 whose offset plus size wraps around 2^32, and seeded mutations of valid datagrams
// (bit flips, truncation, extension, header fields set to edge values, channel names without
// their NUL or too long, the other magic).
#pragma once

#include <algorithm>
#include <cstdint>
#include <random>
#include <string>
#include <vector>

namespace arbor::testing {

using Datagram = std::vector<std::uint8_t>;

inline void putBe32(Datagram& d, std::size_t at, std::uint32_t v) {
  d[at] = static_cast<std::uint8_t>(v >> 24);
  d[at + 1] = static_cast<std::uint8_t>(v >> 16);
  d[at + 2] = static_cast<std::uint8_t>(v >> 8);
  d[at + 3] = static_cast<std::uint8_t>(v);
}

inline void putBe16(Datagram& d, std::size_t at, std::uint16_t v) {
  d[at] = static_cast<std::uint8_t>(v >> 8);
  d[at + 1] = static_cast<std::uint8_t>(v);
}

/// Appends `n` bytes (an index loop: GCC 12 warns falsely on vector::insert after a resize).
inline void append(Datagram& d, const std::uint8_t* bytes, std::size_t n) {
  const std::size_t at = d.size();
  d.resize(at + n);
  for (std::size_t k = 0; k < n; ++k) d[at + k] = bytes[k];
}

inline void appendChannel(Datagram& d, const std::string& channel) {
  append(d, reinterpret_cast<const std::uint8_t*>(channel.c_str()), channel.size() + 1);
}

/// `data` on `channel` as liblcm sends it: one LC02 datagram when the channel, its NUL and the
/// data fit in `short_max` bytes (65,499 on Linux), else LC03 fragments of `fragment_max` bytes
/// of payload each (65,487 on Linux; 1,423 on macOS), fragment 0's starting with the channel.
inline std::vector<Datagram> lcmDatagrams(const std::string& channel,
                                          const std::vector<std::uint8_t>& data,
                                          std::uint32_t seqno, std::size_t short_max = 65499,
                                          std::size_t fragment_max = 65487) {
  const std::size_t payload = channel.size() + 1 + data.size();
  std::vector<Datagram> out;
  if (payload <= short_max) {
    Datagram d(8);
    putBe32(d, 0, 0x4c433032);
    putBe32(d, 4, seqno);
    appendChannel(d, channel);
    append(d, data.data(), data.size());
    out.push_back(d);
    return out;
  }
  const std::size_t count = payload / fragment_max + (payload % fragment_max != 0);
  std::size_t offset = 0;
  for (std::size_t k = 0; k < count; ++k) {
    Datagram d(20);
    putBe32(d, 0, 0x4c433033);
    putBe32(d, 4, seqno);
    putBe32(d, 8, static_cast<std::uint32_t>(data.size()));
    putBe32(d, 12, static_cast<std::uint32_t>(offset));
    putBe16(d, 16, static_cast<std::uint16_t>(k));
    putBe16(d, 18, static_cast<std::uint16_t>(count));
    std::size_t room = fragment_max;
    if (k == 0) {
      appendChannel(d, channel);
      room -= channel.size() + 1;
    }
    const std::size_t n = std::min(room, data.size() - offset);
    append(d, data.data() + offset, n);
    offset += n;
    out.push_back(d);
  }
  return out;
}

/// Issue 56's datagram: 544 bytes, LC03 fragment 0 of a 1,000-byte message on `channel`, at
/// offset 2^32 − 256, so offset + its data size wraps around 2^32 to below 1,000 (liblcm 1.3's
/// check passes and its memcpy writes 4 GiB past its buffer).
inline Datagram wrappingFragment(const std::string& channel) {
  Datagram d(20);
  putBe32(d, 0, 0x4c433033);
  putBe32(d, 4, 7);
  putBe32(d, 8, 1000);
  putBe32(d, 12, 0xFFFFFF00u);
  putBe16(d, 16, 0);
  putBe16(d, 18, 2);
  appendChannel(d, channel);
  d.resize(544, 0xAB);
  return d;
}

/// Valid datagrams on `channels` (random data: no decoder accepts it as a message), some
/// fragmented with macOS's small fragments, then mutated; `count` in all.
inline std::vector<Datagram> mutatedDatagrams(const std::vector<std::string>& channels,
                                              std::size_t count, std::uint32_t seed) {
  std::mt19937 rng(seed);
  const auto uniform = [&](std::size_t lo, std::size_t hi) {
    return std::uniform_int_distribution<std::size_t>(lo, hi)(rng);
  };
  const std::uint32_t edge_values[] = {
      0, 1, 2, 255, 256, 1000, 0x7FFFFFFF, 0x80000000, 0xFFFFFF00, 0xFFFFFFFE, 0xFFFFFFFF};
  std::vector<Datagram> out;
  std::uint32_t seqno = 1;
  while (out.size() < count) {
    const std::string& channel = channels[uniform(0, channels.size() - 1)];
    std::vector<std::uint8_t> data(uniform(0, 1) ? uniform(1, 300) : uniform(1500, 6000));
    for (auto& b : data) b = static_cast<std::uint8_t>(uniform(0, 255));
    std::vector<Datagram> message = lcmDatagrams(channel, data, seqno++, 1435, 1423);
    for (Datagram& d : message) {
      switch (uniform(0, 7)) {
        case 0:  // kept valid
          break;
        case 1:  // bit flips anywhere
          for (std::size_t k = uniform(1, 4); k > 0; --k)
            d[uniform(0, d.size() - 1)] ^= 1u << uniform(0, 7);
          break;
        case 2:  // truncated
          d.resize(uniform(0, d.size() - 1));
          break;
        case 3:  // extended
          for (std::size_t k = uniform(1, 64); k > 0; --k)
            d.push_back(static_cast<std::uint8_t>(uniform(0, 255)));
          break;
        case 4:  // a header field (a 32-bit one at 4, 8 or 12; or fragment number and count)
          if (d.size() >= 20) {
            const std::uint32_t v = edge_values[uniform(0, std::size(edge_values) - 1)];
            switch (uniform(0, 4)) {
              case 0:
                putBe32(d, 4, v);
                break;
              case 1:
                putBe32(d, 8, v);
                break;
              case 2:
                putBe32(d, 12, v);
                break;
              case 3:
                putBe16(d, 16, static_cast<std::uint16_t>(v));
                break;
              default:
                putBe16(d, 18, static_cast<std::uint16_t>(v));
                break;
            }
          }
          break;
        case 5: {  // the channel's NUL overwritten, or a name of 64 bytes or more
          const std::size_t at = (d[3] == 0x32 ? 8 : 20) + channel.size();
          if (at < d.size()) d[at] = 'A';
          if (uniform(0, 1) && d.size() > at)
            d.insert(d.begin() + static_cast<std::ptrdiff_t>(at), 64, 'B');
          break;
        }
        case 6:  // the other magic
          d[3] = d[3] == 0x32 ? 0x33 : 0x32;
          break;
        default:  // repeated
          out.push_back(d);
          break;
      }
      out.push_back(d);
      if (out.size() == count) break;
    }
  }
  return out;
}

}  // namespace arbor::testing
