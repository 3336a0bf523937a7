#include "arbor_slam/tools/serve/lcm_tuning.h"

#include <dirent.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <sys/socket.h>
#include <sys/stat.h>

#include <algorithm>
#include <cstdlib>
#include <stdexcept>

namespace arbor::serve {

bool tuneLcmTransport(lcm::LCM& lcm, const std::string& url) {
  if (url.rfind("tcpq://", 0) != 0) return false;
  const int fd = lcm.getFileno();  // tcpq: the socket to the hub
  if (fd < 0) return false;
  const int one = 1;
  return setsockopt(fd, IPPROTO_TCP, TCP_NODELAY, &one, sizeof one) == 0;
}

void armQuickAck(lcm::LCM& lcm) {
  const int fd = lcm.getFileno();
  if (fd < 0) return;
  const int one = 1;
  setsockopt(fd, IPPROTO_TCP, TCP_QUICKACK, &one, sizeof one);  // fails harmlessly if not TCP
}

namespace {

// The URL LCM opens for `url` ("" is LCM_DEFAULT_URL or udpm's default).
std::string effectiveUrl(const std::string& url) {
  if (!url.empty()) return url;
  const char* env = std::getenv("LCM_DEFAULT_URL");
  return env && *env ? std::string(env) : std::string("udpm://239.255.76.67:7667");
}

}  // namespace

bool isUdpmUrl(const std::string& url) { return effectiveUrl(url).rfind("udpm://", 0) == 0; }

std::string withReceiveBuffer(const std::string& url, std::int64_t bytes, UrlOption existing) {
  if (!isUdpmUrl(url)) {
    throw std::invalid_argument("a receive buffer size applies to udpm:// only, not '" +
                                effectiveUrl(url) + "'");
  }
  if (bytes <= 0) {
    throw std::invalid_argument("the receive buffer size must be > 0 bytes, not " +
                                std::to_string(bytes));
  }
  const std::string u = effectiveUrl(url);
  const std::string option = "recv_buf_size=" + std::to_string(bytes);
  const size_t at = u.find("recv_buf_size=");
  if (at == std::string::npos) return u + (u.find('?') == std::string::npos ? "?" : "&") + option;
  if (existing == UrlOption::kKeep) return u;
  const size_t end = u.find('&', at);
  return u.substr(0, at) + option + (end == std::string::npos ? "" : u.substr(end));
}

int udpmPort(const std::string& url) {
  if (!isUdpmUrl(url)) return -1;
  std::string u = effectiveUrl(url).substr(7);  // after "udpm://"
  u = u.substr(0, u.find('?'));
  const size_t colon = u.rfind(':');
  if (colon == std::string::npos) return 7667;
  try {
    return std::stoi(u.substr(colon + 1));
  } catch (const std::exception&) {
    return -1;
  }
}

std::int64_t udpReceiveBufferBytes(int port) {
  std::int64_t best = 0;
  DIR* dir = opendir("/proc/self/fd");
  if (!dir) return 0;
  while (const dirent* e = readdir(dir)) {
    char* end = nullptr;
    const long fd = std::strtol(e->d_name, &end, 10);
    if (end == e->d_name || *end != '\0' || fd == dirfd(dir)) continue;
    struct stat st {};
    if (fstat(static_cast<int>(fd), &st) != 0 || !S_ISSOCK(st.st_mode)) continue;
    int type = 0;
    socklen_t len = sizeof type;
    if (getsockopt(static_cast<int>(fd), SOL_SOCKET, SO_TYPE, &type, &len) != 0 ||
        type != SOCK_DGRAM)
      continue;
    sockaddr_in addr{};
    len = sizeof addr;
    if (getsockname(static_cast<int>(fd), reinterpret_cast<sockaddr*>(&addr), &len) != 0 ||
        addr.sin_family != AF_INET || ntohs(addr.sin_port) != port)
      continue;
    int size = 0;
    len = sizeof size;
    if (getsockopt(static_cast<int>(fd), SOL_SOCKET, SO_RCVBUF, &size, &len) == 0)
      best = std::max<std::int64_t>(best, size);
  }
  closedir(dir);
  return best;
}

}  // namespace arbor::serve
