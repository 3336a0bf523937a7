// A bounded check of an LCM tcpq hub before liblcm connects to it. liblcm 1.3.1's tcpq
// provider (lcm/lcm_tcpq.c) connects, sends its greeting (MAGIC_CLIENT 0x287617fb, then
// PROTOCOL_VERSION 0x0100, each a big-endian uint32) and then blocks in recv() for the hub's
// answer (MAGIC_SERVER 0x287617fa and its version) without a timeout: a hub that accepts the
// connection and never answers holds lcm_create forever. This check does the same exchange on a
// socket of its own with a deadline, so a link is only created once the hub has answered.
#pragma once

#include <string>

namespace arbor::serve {

/// The host and port of a tcpq URL ("tcpq://HOST[:PORT][?options]"; liblcm's default port
/// 7700); false for another provider or a port that is not 1..65535.
bool tcpqHostPort(const std::string& url, std::string* host, int* port);

/// Connects to the hub of a tcpq URL, sends liblcm's greeting and reads the hub's answer, all
/// within `timeout_ms`; "" when the hub answered as an LCM hub does, else why not ("connection
/// refused", "accepted the connection but did not answer LCM's handshake within 2000 ms", …).
/// The connection is closed either way. Never throws.
std::string tcpqHandshakeProblem(const std::string& url, int timeout_ms);

}  // namespace arbor::serve
