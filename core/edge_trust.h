// How a relative-pose edge is treated by robust smoothing, as chosen by whoever sends it (the
// API, an LCM edge_t, a g2o file's ARBOR_EDGE line): the trust and, for a judged edge, the
// kernel it graduates towards (KernelKind::kNone: the smoother's --kernel).
#pragma once

namespace arbor {

enum class EdgeTrust {
  kByRule,   ///< odometry (|from − to| = 1) trusted, any other edge a loop closure to judge
  kTrusted,  ///< the sender vouches for it: weight 1 for good, whatever its ids
  kRobust,   ///< judged even when its ids are consecutive (a front end's odometry it doubts)
};

/// "default" | "trusted" | "robust".
inline const char* toString(EdgeTrust trust) {
  switch (trust) {
    case EdgeTrust::kByRule:
      return "default";
    case EdgeTrust::kTrusted:
      return "trusted";
    case EdgeTrust::kRobust:
      return "robust";
  }
  return "unknown";
}

}  // namespace arbor
