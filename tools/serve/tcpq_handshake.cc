#include "arbor_slam/tools/serve/tcpq_handshake.h"

#include <arpa/inet.h>
#include <fcntl.h>
#include <netdb.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cstdint>
#include <cstring>

namespace arbor::serve {
namespace {

constexpr std::uint32_t kMagicServer = 0x287617fa;  // lcm_tcpq.c: first word the hub sends
constexpr std::uint32_t kMagicClient = 0x287617fb;  // first word the client sends
constexpr std::uint32_t kProtocolVersion = 0x0100;

using Clock = std::chrono::steady_clock;

/// Milliseconds left until `deadline` (≥ 0).
int msLeft(Clock::time_point deadline) {
  const auto left =
      std::chrono::duration_cast<std::chrono::milliseconds>(deadline - Clock::now()).count();
  return left > 0 ? static_cast<int>(left) : 0;
}

class Socket {
 public:
  explicit Socket(int fd) : fd_(fd) {}
  ~Socket() {
    if (fd_ >= 0) ::close(fd_);
  }
  Socket(const Socket&) = delete;
  Socket& operator=(const Socket&) = delete;
  int fd() const { return fd_; }

 private:
  int fd_;
};

/// Waits until `fd` is ready for `events` or the deadline; false on timeout.
bool waitFor(int fd, short events, Clock::time_point deadline) {
  for (;;) {
    pollfd p{fd, events, 0};
    const int r = ::poll(&p, 1, msLeft(deadline));
    if (r > 0) return true;
    if (r == 0) return false;
    if (errno != EINTR) return false;
  }
}

}  // namespace

bool tcpqHostPort(const std::string& url, std::string* host, int* port) {
  const std::string scheme = "tcpq://";
  if (url.rfind(scheme, 0) != 0) return false;
  std::string rest = url.substr(scheme.size());
  rest = rest.substr(0, rest.find('?'));
  const size_t colon = rest.rfind(':');
  *host = colon == std::string::npos ? rest : rest.substr(0, colon);
  if (host->empty()) *host = "127.0.0.1";
  *port = 7700;
  if (colon != std::string::npos) {
    const std::string digits = rest.substr(colon + 1);
    if (digits.empty() || digits.size() > 5 ||
        digits.find_first_not_of("0123456789") != std::string::npos) {
      return false;
    }
    *port = std::stoi(digits);
  }
  return *port >= 1 && *port <= 65535;
}

std::string tcpqHandshakeProblem(const std::string& url, int timeout_ms) {
  std::string host;
  int port = 0;
  if (!tcpqHostPort(url, &host, &port)) return "'" + url + "' is not a tcpq://HOST:PORT URL";
  const std::string where = host + ":" + std::to_string(port);
  const auto deadline = Clock::now() + std::chrono::milliseconds(timeout_ms);
  addrinfo hints{};
  hints.ai_family = AF_INET;
  hints.ai_socktype = SOCK_STREAM;
  addrinfo* found = nullptr;
  if (::getaddrinfo(host.c_str(), std::to_string(port).c_str(), &hints, &found) != 0 ||
      found == nullptr) {
    return "cannot resolve " + host;
  }
  Socket s(::socket(AF_INET, SOCK_STREAM | SOCK_NONBLOCK | SOCK_CLOEXEC, 0));
  if (s.fd() < 0) {
    ::freeaddrinfo(found);
    return std::string("no socket: ") + std::strerror(errno);
  }
  const int c = ::connect(s.fd(), found->ai_addr, found->ai_addrlen);
  ::freeaddrinfo(found);
  if (c != 0 && errno != EINPROGRESS) return where + ": " + std::strerror(errno);
  if (c != 0) {
    if (!waitFor(s.fd(), POLLOUT, deadline)) {
      return where + ": no connection within " + std::to_string(timeout_ms) + " ms";
    }
    int error = 0;
    socklen_t length = sizeof(error);
    ::getsockopt(s.fd(), SOL_SOCKET, SO_ERROR, &error, &length);
    if (error != 0) return where + ": " + std::strerror(error);
  }
  const std::uint32_t hello[2] = {htonl(kMagicClient), htonl(kProtocolVersion)};
  if (::send(s.fd(), hello, sizeof(hello), MSG_NOSIGNAL) != static_cast<ssize_t>(sizeof(hello))) {
    return where + ": the greeting could not be sent: " + std::strerror(errno);
  }
  std::uint32_t answer[2] = {0, 0};
  size_t got = 0;
  auto* bytes = reinterpret_cast<unsigned char*>(answer);
  while (got < sizeof(answer)) {
    if (!waitFor(s.fd(), POLLIN, deadline)) {
      return where + " accepted the connection but did not answer LCM's handshake within " +
             std::to_string(timeout_ms) + " ms";
    }
    const ssize_t n = ::recv(s.fd(), bytes + got, sizeof(answer) - got, 0);
    if (n == 0) return where + " closed the connection during LCM's handshake";
    if (n < 0) {
      if (errno == EINTR || errno == EAGAIN) continue;
      return where + ": " + std::strerror(errno);
    }
    got += static_cast<size_t>(n);
  }
  if (ntohl(answer[0]) != kMagicServer) return where + " answered, but not as an LCM hub";
  return "";
}

}  // namespace arbor::serve
