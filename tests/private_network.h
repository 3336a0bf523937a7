// A private network namespace for tests that use LCM's UDP multicast (udpm://): the calling
// thread, and every thread and child process it starts afterwards, move into a namespace of
// their own whose only interface is loopback, brought up with multicast on and 224.0.0.0/4
// routed to it. A udpm URL with ttl=0 (privateUdpmUrl) then never reaches the machine's network:
// the namespace has no other interface to send on.
//
// As root this is unshare(CLONE_NEWNET); unprivileged, a user namespace mapping our uid to root
// as well (only before any other thread exists). Where neither is permitted, enter() says why,
// and the test skips. leave() returns to the namespace the process started in (root only),
// for a test of another transport later in the same process.
#pragma once

#include <fcntl.h>
#include <net/if.h>
#include <sched.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <fstream>
#include <string>
#include <vector>

extern char** environ;

namespace arbor::testing {

class PrivateNetwork {
 public:
  /// Moves the calling thread into the private namespace (made on the first call); "" when
  /// inside, else why not.
  static std::string enter() {
    State& s = state();
    if (s.original < 0) s.original = open("/proc/thread-self/ns/net", O_RDONLY | O_CLOEXEC);
    if (s.inside) return "";
    if (s.private_ns >= 0) {
      if (setns(s.private_ns, CLONE_NEWNET) != 0) return why("setns into the private namespace");
      s.inside = true;
      return "";
    }
    if (!s.failure.empty()) return s.failure;
    if (unshare(CLONE_NEWNET) != 0) {
      const std::string as_root = why("unshare(CLONE_NEWNET)");
      if (unshare(CLONE_NEWUSER | CLONE_NEWNET) != 0) {
        s.failure = as_root + "; " + why("unshare(CLONE_NEWUSER | CLONE_NEWNET)");
        return s.failure;
      }
      const std::string uid = std::to_string(getuid()), gid = std::to_string(getgid());
      if (!write("/proc/self/setgroups", "deny") ||
          !write("/proc/self/uid_map", "0 " + uid + " 1") ||
          !write("/proc/self/gid_map", "0 " + gid + " 1")) {
        s.failure = "cannot map the user namespace's ids";
        return s.failure;
      }
      s.in_user_namespace = true;
    }
    for (const std::vector<std::string>& cmd :
         {std::vector<std::string>{"ip", "link", "set", "lo", "up"},
          std::vector<std::string>{"ip", "link", "set", "lo", "multicast", "on"},
          std::vector<std::string>{"ip", "route", "add", "224.0.0.0/4", "dev", "lo"}}) {
      const std::string failed = run(cmd);
      if (!failed.empty()) {
        s.failure = failed;
        return s.failure;
      }
    }
    // Loopback only: nothing sent here can leave the machine.
    if (interfaces() != std::vector<std::string>{"lo"}) {
      s.failure = "the new namespace has interfaces besides lo";
      return s.failure;
    }
    s.private_ns = open("/proc/thread-self/ns/net", O_RDONLY | O_CLOEXEC);
    s.inside = true;
    return "";
  }

  /// Back to the namespace the process started in; "" when there (or never left), else why not.
  static std::string leave() {
    State& s = state();
    if (!s.inside) return "";
    if (s.in_user_namespace) return "inside a user namespace: the original network is out of reach";
    if (s.original < 0 || setns(s.original, CLONE_NEWNET) != 0)
      return why("setns into the original namespace");
    s.inside = false;
    return "";
  }

  static bool inside() { return state().inside; }

  /// The interfaces of the calling thread's namespace.
  static std::vector<std::string> interfaces() {
    std::vector<std::string> names;
    if (struct if_nameindex* list = ::if_nameindex()) {
      for (struct if_nameindex* i = list; i->if_index != 0; ++i) names.emplace_back(i->if_name);
      ::if_freenameindex(list);
    }
    return names;
  }

 private:
  struct State {
    int original = -1, private_ns = -1;
    bool inside = false, in_user_namespace = false;
    std::string failure;
  };
  static State& state() {
    static State s;
    return s;
  }
  static std::string why(const std::string& what) { return what + ": " + std::strerror(errno); }
  static bool write(const std::string& path, const std::string& text) {
    std::ofstream out(path);
    out << text;
    out.close();
    return static_cast<bool>(out);
  }
  static std::string run(const std::vector<std::string>& argv) {
    std::vector<char*> args;
    for (const auto& a : argv) args.push_back(const_cast<char*>(a.c_str()));
    args.push_back(nullptr);
    pid_t pid = -1;
    std::string line;
    for (const auto& a : argv) line += (line.empty() ? "" : " ") + a;
    if (posix_spawnp(&pid, args[0], nullptr, nullptr, args.data(), environ) != 0)
      return "cannot run '" + line + "'";
    int status = 0;
    waitpid(pid, &status, 0);
    if (!WIFEXITED(status) || WEXITSTATUS(status) != 0) return "'" + line + "' failed";
    return "";
  }
};

/// The udpm URL of the tests: LCM's default group on `port`, ttl=0, and a receive buffer of
/// `recv_buf_bytes` (0: LCM's default) for every instance that subscribes.
inline std::string privateUdpmUrl(int port, long recv_buf_bytes = 0) {
  std::string url = "udpm://239.255.76.67:" + std::to_string(port) + "?ttl=0";
  if (recv_buf_bytes > 0) url += "&recv_buf_size=" + std::to_string(recv_buf_bytes);
  return url;
}

}  // namespace arbor::testing
