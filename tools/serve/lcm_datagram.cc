#include "arbor_slam/tools/serve/lcm_datagram.h"

#include <algorithm>
#include <cstdio>
#include <cstring>
#include <utility>

namespace arbor::serve {
namespace {

std::uint32_t be32(const std::uint8_t* p) {
  return (std::uint32_t{p[0]} << 24) | (std::uint32_t{p[1]} << 16) | (std::uint32_t{p[2]} << 8) |
         std::uint32_t{p[3]};
}

std::uint16_t be16(const std::uint8_t* p) { return static_cast<std::uint16_t>((p[0] << 8) | p[1]); }

DatagramOutcome refusal(const char* reason, std::string detail) {
  DatagramOutcome o;
  o.refused = reason;
  o.detail = std::move(detail);
  return o;
}

std::size_t words(std::uint64_t bits) { return static_cast<std::size_t>((bits + 63) / 64); }

bool bit(const std::vector<std::uint64_t>& v, std::uint64_t k) {
  return (v[k / 64] >> (k % 64)) & 1;
}

void setBit(std::vector<std::uint64_t>& v, std::uint64_t k) {
  v[k / 64] |= std::uint64_t{1} << (k % 64);
}

}  // namespace

std::string lcmChannelAt(const std::uint8_t* bytes, std::size_t size) {
  const std::size_t n = std::min(size, kLcmMaxChannelBytes + 1);
  const void* nul = std::memchr(bytes, 0, n);
  if (nul == nullptr || nul == bytes) return "";
  return std::string(reinterpret_cast<const char*>(bytes),
                     static_cast<const std::uint8_t*>(nul) - bytes);
}

LcmDatagramAssembler::LcmDatagramAssembler(DatagramLimits limits, Wants wants)
    : limits_(limits), wants_(std::move(wants)) {}

DatagramOutcome LcmDatagramAssembler::add(std::uint64_t source, const std::uint8_t* bytes,
                                          std::size_t size) {
  ++datagrams_;
  if (size < kLcmShortHeaderBytes) {
    return refusal("short", std::to_string(size) + " bytes, under any LCM header");
  }
  const std::uint32_t magic = be32(bytes);
  if (magic == kLcmMagicShort) return shortMessage(bytes, size);
  if (magic == kLcmMagicLong) return fragment(source, bytes, size);
  return refusal(
      "magic", "magic 0x" + [&] {
        char hex[9];
        std::snprintf(hex, sizeof hex, "%08x", magic);
        return std::string(hex);
      }() + " is neither LC02 nor LC03");
}

DatagramOutcome LcmDatagramAssembler::shortMessage(const std::uint8_t* bytes, std::size_t size) {
  const std::string channel =
      lcmChannelAt(bytes + kLcmShortHeaderBytes, size - kLcmShortHeaderBytes);
  if (channel.empty()) {
    return refusal("channel", "LC02 without a NUL-terminated channel name of 1 to 63 bytes");
  }
  if (!wants_(channel)) return {};
  DatagramOutcome o;
  o.complete = true;
  o.channel = channel;
  o.data = bytes + kLcmShortHeaderBytes + channel.size() + 1;
  o.size = size - kLcmShortHeaderBytes - channel.size() - 1;
  return o;
}

DatagramOutcome LcmDatagramAssembler::fragment(std::uint64_t source, const std::uint8_t* bytes,
                                               std::size_t size) {
  if (size < kLcmLongHeaderBytes) {
    return refusal("short", "LC03 of " + std::to_string(size) + " bytes, under its 20-byte header");
  }
  const std::uint32_t seqno = be32(bytes + 4);
  const std::uint32_t msg_size = be32(bytes + 8);
  const std::uint32_t offset = be32(bytes + 12);
  const std::uint16_t number = be16(bytes + 16);
  const std::uint16_t count = be16(bytes + 18);
  const std::uint8_t* data = bytes + kLcmLongHeaderBytes;
  std::size_t length = size - kLcmLongHeaderBytes;
  const std::string where = "fragment " + std::to_string(number) + " of " + std::to_string(count) +
                            " (offset " + std::to_string(offset) + ", message " +
                            std::to_string(msg_size) + " bytes)";
  if (msg_size == 0 || msg_size > limits_.max_message_bytes) {
    return refusal("message size",
                   where + ": not 1 to " + std::to_string(limits_.max_message_bytes) + " bytes");
  }
  if (count == 0 || number >= count) return refusal("fragment number", where);
  std::string channel;
  if (number == 0) {
    channel = lcmChannelAt(data, length);
    if (channel.empty()) {
      return refusal("channel", where + ": no NUL-terminated channel name of 1 to 63 bytes");
    }
    data += channel.size() + 1;
    length -= channel.size() + 1;
    if (offset != 0) return refusal("fragment range", where + ": fragment 0 not at offset 0");
  }
  if (length == 0) return refusal("fragment range", where + ": no data");
  if (std::uint64_t{offset} + length > msg_size) {
    return refusal("fragment range",
                   where + ": " + std::to_string(length) + " bytes reach past the message's end");
  }
  auto it = partials_.find(source);
  if (it != partials_.end() && it->second.seqno != seqno) {
    drop(source);  // the sender moved on: the rest of that message is not coming
    it = partials_.end();
  }
  if (it != partials_.end() && (it->second.size != msg_size || it->second.count != count)) {
    const std::string announced = std::to_string(it->second.size) + " bytes in " +
                                  std::to_string(it->second.count) + " fragments";
    drop(source);
    return refusal("fragment inconsistent", where + ": its message was announced as " + announced);
  }
  Partial* p = it != partials_.end() ? &it->second : nullptr;
  if (p == nullptr) {
    if (number != 0 || !wants_(channel)) return {};  // not ours, or its start was lost
    p = start(source, seqno, msg_size, count, channel);
    if (p == nullptr) {
      return refusal("message size", where + ": more than the reassembly table's " +
                                         std::to_string(limits_.max_partial_bytes) + " bytes");
    }
  }
  if (bit(p->numbers, number)) {
    drop(source);
    return refusal("fragment overlap", where + ": received twice");
  }
  for (std::uint64_t k = offset; k < std::uint64_t{offset} + length; ++k) {
    if (bit(p->covered, k)) {
      drop(source);
      return refusal("fragment overlap", where + ": byte " + std::to_string(k) + " received twice");
    }
  }
  std::memcpy(p->data.data() + offset, data, length);
  for (std::uint64_t k = offset; k < std::uint64_t{offset} + length; ++k) setBit(p->covered, k);
  setBit(p->numbers, number);
  ++p->fragments;
  p->covered_bytes += length;
  p->touched = datagrams_;
  const bool bytes_done = p->covered_bytes == p->size, fragments_done = p->fragments == p->count;
  if (!bytes_done && !fragments_done) return {};
  if (bytes_done != fragments_done) {
    const std::string got = std::to_string(p->covered_bytes) + " bytes in " +
                            std::to_string(p->fragments) + " fragments";
    drop(source);
    return refusal("fragment count", where + ": " + got);
  }
  DatagramOutcome o;
  o.complete = true;
  o.channel = p->channel;
  partial_bytes_ -= p->bytes();
  completed_ = std::move(p->data);
  o.data = completed_.data();
  o.size = completed_.size();
  partials_.erase(source);
  return o;
}

LcmDatagramAssembler::Partial* LcmDatagramAssembler::start(std::uint64_t source,
                                                           std::uint32_t seqno,
                                                           std::uint32_t msg_size,
                                                           std::uint16_t count,
                                                           const std::string& channel) {
  const std::size_t need = msg_size + 8 * (words(msg_size) + words(count));
  if (need > limits_.max_partial_bytes || limits_.max_partial_messages == 0) return nullptr;
  while (!partials_.empty() && (partials_.size() >= limits_.max_partial_messages ||
                                partial_bytes_ + need > limits_.max_partial_bytes)) {
    const auto oldest = std::min_element(
        partials_.begin(), partials_.end(),
        [](const auto& a, const auto& b) { return a.second.touched < b.second.touched; });
    drop(oldest->first);
  }
  Partial& p = partials_[source];
  p.seqno = seqno;
  p.size = msg_size;
  p.count = count;
  p.channel = channel;
  p.data.assign(msg_size, 0);
  p.covered.assign(words(msg_size), 0);
  p.numbers.assign(words(count), 0);
  partial_bytes_ += p.bytes();
  return &p;
}

void LcmDatagramAssembler::drop(std::uint64_t source) {
  const auto it = partials_.find(source);
  if (it == partials_.end()) return;
  partial_bytes_ -= it->second.bytes();
  partials_.erase(it);
  ++dropped_partials_;
}

}  // namespace arbor::serve
