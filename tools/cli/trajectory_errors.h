// An estimate against a reference trajectory, by evo's definitions (evo_ape, evo_rpe with their
// defaults; docs/files.md, "arbor plot"):
//   association  each estimate pose with the reference pose nearest in time, kept when within
//                max_diff (evo's t_max_diff, 0.01 s; ids and line numbers match exactly);
//   ATE          the RMSE of ‖R pₖ + t − qₖ‖ over the associated positions after the rigid SE(3)
//                alignment (R, t) of the estimate onto the reference (Umeyama without scale,
//                core/rigid_alignment.h; evo_ape --align);
//   RPE          the RMSE of the translation of Eₖ = (Qₖ⁻¹ Qₖ₊₁)⁻¹ (Pₖ⁻¹ Pₖ₊₁) over the pairs of
//                associated poses one step apart (evo_rpe --delta 1 --delta_unit f); P the
//                estimate, Q the reference. It does not depend on a rigid alignment.
#pragma once

#include <utility>
#include <vector>

#include "arbor_slam/io/trajectory_reader.h"

namespace arbor::cli {

struct TrajectoryErrors {
  int associated = 0;  ///< pose pairs associated
  SE3 alignment;       ///< the estimate's rigid move onto the reference
  double ate_rmse = 0, ate_mean = 0, ate_max = 0;
  int rpe_pairs = 0;  ///< associated poses one step apart
  double rpe_rmse = 0;
};

/// (estimate index, reference index) pairs, in the estimate's order.
std::vector<std::pair<int, int>> associateByTime(const Trajectory& estimate,
                                                 const Trajectory& reference,
                                                 double max_diff = 0.01);

/// The errors above; throws std::invalid_argument naming the counts when fewer than 2 poses
/// associate (nothing to align or to step along).
TrajectoryErrors trajectoryErrors(const Trajectory& estimate, const Trajectory& reference,
                                  double max_diff = 0.01);

}  // namespace arbor::cli
