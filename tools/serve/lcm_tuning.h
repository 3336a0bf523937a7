// Socket tuning for LCM's providers.
// tcpq://: liblcm 1.3 leaves Nagle's algorithm on, and the Java hub (lcm.lcm.TCPService) writes
// each message in five small writes on a socket with Nagle on, so every message after the first
// small write waits for our (delayed, up to 40 ms) ACK. We set TCP_NODELAY on our socket and
// re-arm TCP_QUICKACK before each receive.
// udpm://: a datagram that arrives while the receive socket's buffer is full is dropped by the
// kernel. The buffer is LCM's URL option recv_buf_size (SO_RCVBUF, capped by
// net.core.rmem_max; Linux reports twice the size granted); what a burst needs is in
// docs/lcm.md, "udpm: receive buffer and loss".
#pragma once

#include <cstdint>
#include <string>

#include <lcm/lcm-cpp.hpp>

namespace arbor::serve {

/// For a tcpq:// URL, disables Nagle's algorithm on `lcm`'s socket; returns whether it did.
bool tuneLcmTransport(lcm::LCM& lcm, const std::string& url);

/// Asks the kernel to acknowledge what arrives next at once (TCP_QUICKACK, which Linux clears
/// after use: call before every handle). A no-op on a provider without a TCP socket.
void armQuickAck(lcm::LCM& lcm);

/// Whether `url` is LCM's UDP multicast provider ("udpm://…", or "" for LCM's default, which is
/// udpm unless LCM_DEFAULT_URL says otherwise).
bool isUdpmUrl(const std::string& url);

/// Whether a URL that already names recv_buf_size keeps its own (a default) or gets `bytes` (an
/// explicit request).
enum class UrlOption { kKeep, kReplace };

/// `url` with recv_buf_size=`bytes` (udpm only). Throws std::invalid_argument for another
/// provider or bytes <= 0.
std::string withReceiveBuffer(const std::string& url, std::int64_t bytes,
                              UrlOption existing = UrlOption::kKeep);

/// The UDP port of a udpm URL (LCM's default 7667 when the URL has none); -1 for another
/// provider.
int udpmPort(const std::string& url);

/// The receive buffer the kernel gives this process's UDP socket bound to `port` (SO_RCVBUF, as
/// Linux reports it), the largest if several; 0 if there is none (LCM opens it on the first
/// subscribe).
std::int64_t udpReceiveBufferBytes(int port);

}  // namespace arbor::serve
