#include "arbor_slam/tools/serve/udpm_receiver.h"

#include <arpa/inet.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <stdexcept>

namespace arbor::serve {
namespace {

constexpr int kMaxDatagramsPerReceive = 256;
constexpr std::size_t kDatagramBuffer = 65536;  // above any UDP/IPv4 payload (65,507)

// The value of option `name` in the URL's query (`name=` up to '&'); "" when absent.
std::string option(const std::string& query, const std::string& name) {
  for (std::size_t at = 0; at < query.size();) {
    const std::size_t end = std::min(query.find('&', at), query.size());
    const std::string item = query.substr(at, end - at);
    if (item.rfind(name + "=", 0) == 0) return item.substr(name.size() + 1);
    at = end + 1;
  }
  return "";
}

std::int64_t positive(const std::string& text, const std::string& what, const std::string& url,
                      std::int64_t max) {
  try {
    std::size_t used = 0;
    const long long v = std::stoll(text, &used);
    if (used == text.size() && v > 0 && v <= max) return v;
  } catch (const std::exception&) {
  }
  throw std::invalid_argument("udpm URL '" + url + "': " + what + " '" + text + "' is not 1 to " +
                              std::to_string(max));
}

std::string describe(const sockaddr_in& from) {
  char text[INET_ADDRSTRLEN] = "?";
  inet_ntop(AF_INET, &from.sin_addr, text, sizeof text);
  return std::string(text) + ":" + std::to_string(ntohs(from.sin_port));
}

}  // namespace

UdpmEndpoint parseUdpmUrl(const std::string& url) {
  if (url.rfind("udpm://", 0) != 0) {
    throw std::invalid_argument("'" + url + "' is not a udpm:// URL");
  }
  const std::string rest = url.substr(7);
  const std::size_t q = rest.find('?');
  const std::string address = rest.substr(0, q);
  const std::string query = q == std::string::npos ? "" : rest.substr(q + 1);
  UdpmEndpoint e;
  const std::size_t colon = address.rfind(':');
  const std::string host = address.substr(0, colon);
  if (colon != std::string::npos) {
    e.port = static_cast<int>(positive(address.substr(colon + 1), "port", url, 65535));
  }
  if (inet_pton(AF_INET, host.c_str(), &e.group) != 1 || !IN_MULTICAST(ntohl(e.group.s_addr))) {
    throw std::invalid_argument("udpm URL '" + url + "': '" + host +
                                "' is not a multicast IPv4 address");
  }
  const std::string buf = option(query, "recv_buf_size");
  if (!buf.empty()) e.recv_buf_bytes = positive(buf, "recv_buf_size", url, 2147483647);
  return e;
}

UdpmReceiver::UdpmReceiver(const std::string& url, std::set<std::string> channels,
                           std::function<void(const std::string&)> log, DatagramLimits limits)
    : endpoint_(parseUdpmUrl(url)),
      channels_(std::move(channels)),
      log_(std::move(log)),
      assembler_(limits, [this](const std::string& c) { return channels_.count(c) > 0; }),
      buffer_(kDatagramBuffer) {
  const auto fail = [&](const std::string& what) {
    const std::string why = what + ": " + std::strerror(errno);
    if (fd_ >= 0) ::close(fd_);
    fd_ = -1;
    throw std::runtime_error("udpm receive socket for '" + url + "': " + why);
  };
  fd_ = ::socket(AF_INET, SOCK_DGRAM | SOCK_CLOEXEC, 0);
  if (fd_ < 0) fail("socket");
  const int on = 1;
  if (::setsockopt(fd_, SOL_SOCKET, SO_REUSEADDR, &on, sizeof on) != 0) fail("SO_REUSEADDR");
  if (endpoint_.recv_buf_bytes > 0) {
    const int bytes = static_cast<int>(endpoint_.recv_buf_bytes);
    if (::setsockopt(fd_, SOL_SOCKET, SO_RCVBUF, &bytes, sizeof bytes) != 0) fail("SO_RCVBUF");
  }
  // Bound to the group, not INADDR_ANY as liblcm's: no unicast datagram to the port (from
  // anywhere that routes to this host) and no other group's traffic reaches this socket.
  sockaddr_in addr{};
  addr.sin_family = AF_INET;
  addr.sin_addr = endpoint_.group;
  addr.sin_port = htons(static_cast<std::uint16_t>(endpoint_.port));
  if (::bind(fd_, reinterpret_cast<const sockaddr*>(&addr), sizeof addr) != 0) fail("bind");
  const int off = 0;
  if (::setsockopt(fd_, IPPROTO_IP, IP_MULTICAST_ALL, &off, sizeof off) != 0) {
    fail("IP_MULTICAST_ALL");
  }
  ip_mreq join{};
  join.imr_multiaddr = endpoint_.group;
  join.imr_interface.s_addr = htonl(INADDR_ANY);
  if (::setsockopt(fd_, IPPROTO_IP, IP_ADD_MEMBERSHIP, &join, sizeof join) != 0) {
    fail("joining the multicast group");
  }
}

UdpmReceiver::~UdpmReceiver() {
  if (fd_ >= 0) ::close(fd_);
}

int UdpmReceiver::receive(int timeout_ms, const Deliver& deliver) {
  pollfd p{fd_, POLLIN, 0};
  if (::poll(&p, 1, std::max(0, timeout_ms)) <= 0) return 0;
  int delivered = 0;
  for (int k = 0; k < kMaxDatagramsPerReceive; ++k) {
    sockaddr_in from{};
    socklen_t from_size = sizeof from;
    const ssize_t n = ::recvfrom(fd_, buffer_.data(), buffer_.size(), MSG_DONTWAIT,
                                 reinterpret_cast<sockaddr*>(&from), &from_size);
    if (n < 0) break;  // EAGAIN: none left (or an error the next poll reports again)
    const std::uint64_t source =
        (std::uint64_t{ntohl(from.sin_addr.s_addr)} << 16) | ntohs(from.sin_port);
    const DatagramOutcome o = assembler_.add(source, buffer_.data(), static_cast<std::size_t>(n));
    {
      std::lock_guard<std::mutex> lock(counts_mutex_);
      dropped_partials_ = assembler_.droppedPartials();
    }
    if (!o.refused.empty()) {
      refuse(from, o);
    } else if (o.complete) {
      deliver(o.channel, o.data, o.size);
      ++delivered;
    }
  }
  return delivered;
}

void UdpmReceiver::refuse(const sockaddr_in& from, const DatagramOutcome& outcome) {
  {
    std::lock_guard<std::mutex> lock(counts_mutex_);
    ++refused_[outcome.refused];
  }
  std::int64_t suppressed = 0;
  if (log_ && limiter_.allow(outcome.refused, &suppressed)) {
    log_(LogLimiter::withSuppressed("refused a udpm datagram from " + describe(from) + ": " +
                                        outcome.refused + ": " + outcome.detail,
                                    suppressed));
  }
}

std::map<std::string, std::int64_t> UdpmReceiver::refusedByReason() const {
  std::lock_guard<std::mutex> lock(counts_mutex_);
  return refused_;
}

std::int64_t UdpmReceiver::droppedPartials() const {
  std::lock_guard<std::mutex> lock(counts_mutex_);
  return dropped_partials_;
}

}  // namespace arbor::serve
