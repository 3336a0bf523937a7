// Whether every number of a pose is finite: the check every entry point makes before it accepts
// a pose, a measurement or a transform (factors, the smoothers, the g2o writer).
#pragma once

#include <cmath>

#include "arbor_slam/core/se2.h"
#include "arbor_slam/core/se3.h"

namespace arbor {

/// Translation, cos θ and sin θ all finite.
inline bool allFinite(const SE2& x) {
  return x.translation().allFinite() && std::isfinite(x.cos()) && std::isfinite(x.sin());
}
/// Translation and quaternion all finite.
inline bool allFinite(const SE3& x) {
  return x.translation().allFinite() && x.quaternion().coeffs().allFinite();
}

}  // namespace arbor
