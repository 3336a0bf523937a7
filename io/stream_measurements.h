// The measurements of the streaming service as Arbor's own values, whatever carried them: a
// relative-pose edge, a prior on one pose, an edge command (take an edge back or give it back),
// each with its sender and per-sender seq, and the pose-value layout of the published
// estimates. No transport here: io/lcm_messages.h decodes LCM's bytes into them and encodes
// them back. Includes only core/.
#pragma once

#include <cstdint>
#include <variant>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "arbor_slam/core/edge_trust.h"
#include "arbor_slam/core/pose_graph.h"
#include "arbor_slam/core/robust_kernel.h"
#include "arbor_slam/core/se2.h"
#include "arbor_slam/core/se3.h"

namespace arbor {

/// A validated edge (edge_t over LCM): z measures pose `to` in the frame of pose `from`, with
/// information Ω.
template <class G>
struct StreamEdge {
  using Matrix = Eigen::Matrix<double, G::kDoF, G::kDoF>;
  std::int64_t utime = 0;
  std::int64_t sender = 0;
  std::int64_t seq = 0;
  Key from = 0;
  Key to = 0;
  G z;
  Matrix omega = Matrix::Identity();
  EdgeTrust trust = EdgeTrust::kByRule;   ///< edge_t's trust (edge_v1_t: default)
  KernelKind kernel = KernelKind::kNone;  ///< edge_t's kernel; kNone: KERNEL_DEFAULT
};

using AnyStreamEdge = std::variant<StreamEdge<SE2>, StreamEdge<SE3>>;

/// A validated prior of kind POSE (prior_t over LCM): z measures x_id o (o: the sensor offset) with
/// information Ω (kDoF×kDoF), as PosePriorFactor.
template <class G>
struct StreamPosePrior {
  using Matrix = Eigen::Matrix<double, G::kDoF, G::kDoF>;
  std::int64_t utime = 0;
  std::int64_t sender = 0;
  std::int64_t seq = 0;
  Key id = 0;
  G z;
  G offset;  ///< identity: no offset
  Matrix omega = Matrix::Identity();
};

/// A validated prior of kind POSITION: p measures t(x_id) with information Ω (kDim×kDim), as
/// PositionPriorFactor.
template <class G>
struct StreamPositionPrior {
  using Matrix = Eigen::Matrix<double, G::kDim, G::kDim>;
  std::int64_t utime = 0;
  std::int64_t sender = 0;
  std::int64_t seq = 0;
  Key id = 0;
  typename G::Translation p = G::Translation::Zero();
  Matrix omega = Matrix::Identity();
};

using AnyStreamPrior = std::variant<StreamPosePrior<SE2>, StreamPosePrior<SE3>,
                                    StreamPositionPrior<SE2>, StreamPositionPrior<SE3>>;

/// 2 or 3: the dimension of a prior's poses.
inline int dimOf(const AnyStreamPrior& prior) {
  return prior.index() % 2 == 0 ? 2 : 3;  // SE2, SE3, SE2, SE3
}

/// A validated edge command (edge_command_t over LCM): take back (kDisable) or give back (kEnable)
/// every accepted edge between poses `from` and `to` (OnlineSmoother::disableEdge / enableEdge).
struct StreamEdgeCommand {
  enum class Kind { kDisable, kEnable };
  std::int64_t utime = 0;
  std::int64_t sender = 0;
  std::int64_t seq = 0;
  Kind kind = Kind::kDisable;
  Key from = 0;
  Key to = 0;
};

/// "disable" | "enable"
inline const char* toString(StreamEdgeCommand::Kind kind) {
  return kind == StreamEdgeCommand::Kind::kDisable ? "disable" : "enable";
}

/// A pose's value as fields: translation x y z (z = 0 in 2D); rotation angle, 0, 0, 0 (2D) or
/// quaternion w x y z (3D). The layout of edge_t's and estimate_t's fields, and of Estimate's.
inline void poseToFields(const SE2& pose, double translation[3], double rotation[4]) {
  translation[0] = pose.x();
  translation[1] = pose.y();
  translation[2] = 0;
  rotation[0] = pose.angle();
  rotation[1] = rotation[2] = rotation[3] = 0;
}

inline void poseToFields(const SE3& pose, double translation[3], double rotation[4]) {
  for (int k = 0; k < 3; ++k) translation[k] = pose.translation()[k];
  const Eigen::Quaterniond& q = pose.quaternion();
  rotation[0] = q.w();
  rotation[1] = q.x();
  rotation[2] = q.y();
  rotation[3] = q.z();
}

/// Inverse of poseToFields (no validation: use on trusted values).
template <class G>
G poseFromFields(const double translation[3], const double rotation[4]);

template <>
inline SE2 poseFromFields<SE2>(const double translation[3], const double rotation[4]) {
  return SE2(translation[0], translation[1], rotation[0]);
}

template <>
inline SE3 poseFromFields<SE3>(const double translation[3], const double rotation[4]) {
  return SE3(Eigen::Quaterniond(rotation[0], rotation[1], rotation[2], rotation[3]),
             Eigen::Vector3d(translation[0], translation[1], translation[2]));
}

}  // namespace arbor
