// Socket tuning for LCM's tcpq:// provider. liblcm 1.3 leaves Nagle's algorithm on, and the Java
// hub (lcm.lcm.TCPService) writes each message in five small writes on a socket with Nagle on,
// so every message after the first small write waits for our (delayed, up to 40 ms) ACK. We set
// TCP_NODELAY on our socket and re-arm TCP_QUICKACK before each receive.
#pragma once

#include <string>

#include <lcm/lcm-cpp.hpp>

namespace arbor::serve {

/// For a tcpq:// URL, disables Nagle's algorithm on `lcm`'s socket; returns whether it did.
bool tuneLcmTransport(lcm::LCM& lcm, const std::string& url);

/// Asks the kernel to acknowledge what arrives next at once (TCP_QUICKACK, which Linux clears
/// after use: call before every handle). A no-op on a provider without a TCP socket.
void armQuickAck(lcm::LCM& lcm);

}  // namespace arbor::serve
