#include "arbor/tools/serve/lcm_tuning.h"

#include <netinet/in.h>
#include <netinet/tcp.h>
#include <sys/socket.h>

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

}  // namespace arbor::serve
