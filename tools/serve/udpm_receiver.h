// `arbor serve`'s receive path for udpm:// URLs, in place of liblcm's (whose fragment reassembly
// writes out of bounds on a forged LC03 fragment: one datagram ended the service, issue 56). A
// UDP socket joined to the URL's group with the URL's recv_buf_size as SO_RCVBUF, as liblcm's
// receive socket is, but bound to the group's address and port (liblcm binds INADDR_ANY, which
// also takes unicast datagrams to the port and other groups' on it); every datagram goes through
// LcmDatagramAssembler (tools/serve/lcm_datagram.h: the wire format checked, fragments reassembled
// in a bounded table) and only a complete message on one of the channels asked for is handed on. A
// refused datagram is counted by reason and logged, at most one line per reason a second
// (LogLimiter). liblcm then sees only messages, never a datagram: serve hands them to its
// subscriptions through an in-process memq:// instance (tools/serve/serve_service.h).
#pragma once

#include <netinet/in.h>

#include <cstdint>
#include <functional>
#include <map>
#include <mutex>
#include <set>
#include <string>
#include <vector>

#include "arbor_slam/tools/serve/lcm_datagram.h"
#include "arbor_slam/tools/serve/log_limiter.h"

namespace arbor::serve {

/// What a udpm:// URL names for receiving: udpm://GROUP:PORT?recv_buf_size=N&… (other options,
/// such as ttl, are the sender's).
struct UdpmEndpoint {
  in_addr group{};
  int port = 7667;
  std::int64_t recv_buf_bytes = 0;  ///< 0: the kernel's default
};

/// Throws std::invalid_argument when `url` is not udpm:// with a multicast IPv4 group, a port in
/// 1..65535 and, if given, a recv_buf_size > 0.
UdpmEndpoint parseUdpmUrl(const std::string& url);

class UdpmReceiver {
 public:
  /// A complete message: its channel and data (valid during the call).
  using Deliver =
      std::function<void(const std::string& channel, const std::uint8_t* data, std::size_t size)>;

  /// Opens and joins the socket now. Throws std::runtime_error when the socket cannot be bound
  /// or joined, std::invalid_argument for a URL parseUdpmUrl refuses.
  UdpmReceiver(const std::string& url, std::set<std::string> channels,
               std::function<void(const std::string&)> log, DatagramLimits limits = {});
  ~UdpmReceiver();
  UdpmReceiver(const UdpmReceiver&) = delete;
  UdpmReceiver& operator=(const UdpmReceiver&) = delete;

  /// Waits up to `timeout_ms` for datagrams and reads those waiting (at most 256), handing each
  /// complete message to `deliver`; returns how many it handed on. One thread at a time.
  int receive(int timeout_ms, const Deliver& deliver);

  /// Refused datagrams by reason so far (any thread).
  std::map<std::string, std::int64_t> refusedByReason() const;
  /// Messages whose fragments stopped coming (LcmDatagramAssembler::droppedPartials).
  std::int64_t droppedPartials() const;
  int port() const { return endpoint_.port; }

 private:
  void refuse(const sockaddr_in& from, const DatagramOutcome& outcome);

  UdpmEndpoint endpoint_;
  std::set<std::string> channels_;
  std::function<void(const std::string&)> log_;
  LcmDatagramAssembler assembler_;
  int fd_ = -1;
  std::vector<std::uint8_t> buffer_;
  LogLimiter limiter_;
  mutable std::mutex counts_mutex_;
  std::map<std::string, std::int64_t> refused_;
  std::int64_t dropped_partials_ = 0;
};

}  // namespace arbor::serve
