// What the fuzz targets (tests/fuzz) share: a failed invariant stops the process as a crash
// would (libFuzzer and the driver keep the input), and every LCM decoder run over one message,
// as serve's receive path and the journal's replay hand bytes to them.
#pragma once

#include <climits>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <string>

#include "arbor_slam/io/lcm_messages.h"

namespace arbor::fuzz {

/// Stops the process with `what` when `ok` is false: a finding, as a crash is.
inline void require(bool ok, const char* what, const std::string& detail = "") {
  if (ok) return;
  std::fprintf(stderr, "fuzz target: invariant failed: %s %s\n", what, detail.c_str());
  std::abort();
}

/// A decoder's verdict must come with a detail naming what was wrong (never an empty refusal).
inline void requireDetail(MessageProblem problem, const std::string& detail, const char* type) {
  require(problem == MessageProblem::kNone || !detail.empty(), type, "refused without a detail");
}

/// decodeMessage of M; when it succeeds, the message encodes and decodes again.
template <class M>
void decodeGeneric(const std::uint8_t* data, int size) {
  M message;
  std::string detail;
  const MessageProblem p = decodeMessage(data, size, &message, &detail);
  requireDetail(p, detail, M::getTypeName());
  if (p != MessageProblem::kNone) return;
  const std::vector<std::uint8_t> again = encodeMessage(message);
  M copy;
  require(decodeMessage(again.data(), static_cast<int>(again.size()), &copy, &detail) ==
              MessageProblem::kNone,
          M::getTypeName(), "re-encoded message refused: " + detail);
}

inline void decodeEdgeBytes(const std::uint8_t* data, int size) {
  const EdgeDecoding d = decodeEdge(data, size);
  requireDetail(d.problem, d.detail, "edge");
  if (!d.ok()) return;
  // What was accepted goes out again (serve's journal keeps the bytes; publish re-encodes).
  std::visit(
      [](const auto& edge) {
        const std::vector<std::uint8_t> bytes = encodeMessage(makeEdgeMessage(edge));
        const EdgeDecoding again = decodeEdge(bytes.data(), static_cast<int>(bytes.size()));
        require(again.ok(), "edge", "re-encoded edge refused: " + again.detail);
      },
      d.edge);
}

inline void decodePriorBytes(const std::uint8_t* data, int size) {
  const PriorDecoding d = decodePrior(data, size);
  requireDetail(d.problem, d.detail, "prior");
  if (!d.ok()) return;
  std::visit(
      [](const auto& prior) {
        const std::vector<std::uint8_t> bytes = encodeMessage(makePriorMessage(prior));
        const PriorDecoding again = decodePrior(bytes.data(), static_cast<int>(bytes.size()));
        require(again.ok(), "prior", "re-encoded prior refused: " + again.detail);
      },
      d.prior);
}

inline void decodeEdgeCommandBytes(const std::uint8_t* data, int size) {
  const EdgeCommandDecoding d = decodeEdgeCommand(data, size);
  requireDetail(d.problem, d.detail, "edge command");
  if (!d.ok()) return;
  const std::vector<std::uint8_t> bytes = encodeMessage(makeEdgeCommandMessage(d.command));
  const EdgeCommandDecoding again = decodeEdgeCommand(bytes.data(), static_cast<int>(bytes.size()));
  require(again.ok(), "edge command", "re-encoded command refused: " + again.detail);
}

/// resend_t (loss recovery's requests and window answers): validated, and what is accepted
/// encodes and decodes again.
inline void decodeResendBytes(const std::uint8_t* data, int size) {
  const ResendDecoding d = decodeResend(data, size);
  requireDetail(d.problem, d.detail, "resend_t");
  if (!d.ok()) return;
  const std::vector<std::uint8_t> bytes = encodeMessage(makeResendMessage(d.message));
  const ResendDecoding again = decodeResend(bytes.data(), static_cast<int>(bytes.size()));
  require(again.ok(), "resend_t", "re-encoded message refused: " + again.detail);
}

/// command_t, and the ids of its path as a COVARIANCE command reads them.
inline void decodeCommandBytes(const std::uint8_t* data, int size) {
  command_t command;
  std::string detail;
  const MessageProblem p = decodeMessage(data, size, &command, &detail);
  requireDetail(p, detail, "command_t");
  if (p != MessageProblem::kNone) return;
  try {
    const std::vector<Key> ids = covarianceIds(command.path);
    require(ids.size() == 1 || ids.size() == 2, "covarianceIds", command.path);
    for (Key id : ids) require(id >= 0, "covarianceIds", command.path);
  } catch (const std::invalid_argument& e) {
    require(std::string(e.what()).rfind("covariance", 0) == 0, "covarianceIds' refusal", e.what());
  }
}

/// Every decoder over the same bytes (a message of unknown type, as on a forged channel).
inline void decodeAll(const std::uint8_t* data, std::size_t n) {
  const int size = n > static_cast<std::size_t>(INT_MAX) ? INT_MAX : static_cast<int>(n);
  decodeEdgeBytes(data, size);
  decodePriorBytes(data, size);
  decodeEdgeCommandBytes(data, size);
  decodeCommandBytes(data, size);
  decodeGeneric<estimate_t>(data, size);
  decodeGeneric<status_t>(data, size);
  decodeGeneric<covariance_t>(data, size);
  decodeGeneric<journal_mark_t>(data, size);
  decodeResendBytes(data, size);
}

}  // namespace arbor::fuzz
