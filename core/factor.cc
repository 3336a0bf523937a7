#include "arbor_slam/core/factor.h"

#include <cmath>

#include "arbor_slam/core/finite_pose.h"

namespace arbor {

const char* toString(FactorKind kind) {
  switch (kind) {
    case FactorKind::kRelativePose:
      return "relative_pose";
    case FactorKind::kPosePrior:
      return "pose_prior";
    case FactorKind::kPositionPrior:
      return "position_prior";
    case FactorKind::kCustom:
      return "custom";
  }
  return "unknown";
}

template <class G>
bool Factor<G>::isFinite() const {
  return std::visit(
      [](const auto& f) {
        using F = std::decay_t<decltype(f)>;
        bool ok = f.information.allFinite() && f.sqrt_information_t.allFinite();
        if constexpr (std::is_same_v<F, PositionPriorFactor<G>>)
          ok = ok && f.position.allFinite();
        else if constexpr (std::is_same_v<F, CustomFactor<G>>)
          ok = ok && f.model != nullptr;
        else
          ok = ok && allFinite(f.measurement);
        return ok;
      },
      f_);
}

template class Factor<SE2>;
template class Factor<SE3>;

}  // namespace arbor
