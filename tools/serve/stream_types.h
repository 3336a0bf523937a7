// The values the streaming core (tools/serve/streaming_core.h) exchanges with a transport, in
// Arbor's own types: what arrives (a measurement, validated by the transport's decoder, or its
// refusal), the operator's control commands, and what goes out (estimates, covariance answers).
// No transport here: the LCM adapter (tools/serve/serve_service.h) maps them onto edge_t,
// command_t, estimate_t and covariance_t; another transport maps them onto its own messages.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "arbor_slam/io/stream_measurements.h"

namespace arbor::serve {

/// Which stream a measurement belongs to: each has its own per-sender seq numbers and counts.
enum class MeasurementKind { kEdge, kPrior, kCommand };

/// One message of a measurement stream, as a transport hands it to the core: the validated
/// measurement, or the transport's refusal of its bytes (`problem`, the short reason counted
/// and logged, e.g. "truncated", "information"; `detail`, the log line's explanation).
struct Arrival {
  MeasurementKind kind = MeasurementKind::kEdge;
  std::string problem;        ///< "": valid; else why the transport's decoder refused it
  std::string detail;         ///< with `problem`: what exactly was wrong
  AnyStreamEdge edge;         ///< kEdge
  AnyStreamPrior prior;       ///< kPrior
  StreamEdgeCommand command;  ///< kCommand
  /// Identifies the message's exact contents: a repeat of an earlier (sender, seq) with the
  /// same fingerprint is a duplicate, with another one "seq reused" (EdgeIntake::fingerprint of
  /// the bytes as received, or of a canonical encoding).
  std::uint64_t fingerprint = 0;
  /// The message as received, for a journal that keeps the bytes (the LCM event log does); may
  /// be null (the journal then encodes the measurement). Valid during the call only.
  const void* wire = nullptr;
  int wire_size = 0;
};

/// The operator's commands (command_t over LCM), as the core carries them out.
struct ControlCommand {
  enum class Kind {
    kRefine,       ///< relinearise everything and iterate to convergence now
    kPublishFull,  ///< publish every pose
    kSnapshot,     ///< g2o into the snapshot directory under the plain file name `path`
    kStatus,       ///< publish a status now
    kBatch,        ///< start a batch refinement now
    kClosures,     ///< the closure report into the snapshot directory under `path`
    kCovariance,   ///< answer with the covariance of `ids`
    kUnknown,      ///< a code no kind names (`code`): logged
  };
  Kind kind = Kind::kUnknown;
  int code = 0;             ///< the transport's own code of the command (for kUnknown's log line)
  std::int64_t utime = 0;   ///< the command's time: a covariance answer names it as its request
  std::string path;         ///< kSnapshot, kClosures: a plain file name (checked by the core)
  std::vector<Key> ids;     ///< kCovariance: one or two pose ids
  std::string ids_problem;  ///< kCovariance: why the transport could not read ids ("": none)
};

/// An estimate as published after an update: every pose (`full`) or only those whose value
/// changed since the previous one. Poses as fields (poseToFields): translation x y z, rotation
/// angle 0 0 0 (2D) or quaternion w x y z (3D); estimate_t's layout, field for field.
struct Estimate {
  std::int64_t utime = 0;        ///< µs since the epoch, when published
  std::int64_t last_sender = 0;  ///< sender and seq of the last edge applied (0 0 before any)
  std::int64_t last_seq = 0;
  std::int64_t update = 0;  ///< smoother updates so far
  bool full = false;
  int dim = 0;                    ///< 2 or 3
  std::int32_t total_poses = 0;   ///< poses in the estimate, listed or not
  double F = 0;                   ///< objective Σ eᵀΩe (NaN in a changed-only estimate)
  std::int32_t num_poses = 0;     ///< poses listed
  std::vector<std::int64_t> ids;  ///< [num_poses]
  std::vector<std::vector<double>> translation;  ///< [num_poses][3]
  std::vector<std::vector<double>> rotation;     ///< [num_poses][4]
};

/// The answer to a covariance command: the k×k marginal of one pose or the 2k×2k joint of two
/// (k = 3 in 2D, 6 in 3D; each block [translation; rotation]), or why not (`error`, `matrix`
/// empty).
struct CovarianceAnswer {
  std::int64_t request = 0;  ///< the command's utime
  std::vector<Key> ids;
  std::int64_t update = 0;  ///< the smoother update whose linear system it is
  Eigen::MatrixXd matrix;
  std::string error;  ///< "": answered
};

/// Microseconds since the epoch (a message's utime).
std::int64_t nowMicros();

}  // namespace arbor::serve
