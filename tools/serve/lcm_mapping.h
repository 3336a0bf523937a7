// The LCM adapter's mapping between the streaming core's values (tools/serve/stream_types.h,
// tools/serve/streaming_core.h) and LCM's messages (io/lcm_messages.h): bytes into an Arrival
// (decoded and validated, or refused with the decoder's reason), command_t into a
// ControlCommand, and Estimate, CoreStatus and CovarianceAnswer into estimate_t, status_t and
// covariance_t. Field for field: an Estimate and its estimate_t hold the same doubles.
#pragma once

#include <cstdint>

#include "arbor_slam/io/lcm_messages.h"
#include "arbor_slam/tools/serve/stream_types.h"
#include "arbor_slam/tools/serve/streaming_core.h"

namespace arbor::serve {

/// The bytes of an edge_t (or edge_v1_t), prior_t or edge_command_t, decoded and validated
/// (decodeEdge, decodePrior, decodeEdgeCommand); the fingerprint is the bytes'
/// (EdgeIntake::fingerprint), `wire` points at them.
Arrival arrivalFromBytes(MeasurementKind kind, const void* data, int size);

/// command_t's command and path as the core's command (COVARIANCE's ids read from the path).
ControlCommand controlCommand(const command_t& command);

estimate_t toMessage(const Estimate& estimate);
Estimate fromMessage(const estimate_t& message);
status_t toMessage(const CoreStatus& status);
covariance_t toMessage(const CovarianceAnswer& answer);

}  // namespace arbor::serve
