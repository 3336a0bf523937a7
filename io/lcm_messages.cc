#include "arbor_slam/io/lcm_messages.h"

#include <charconv>
#include <cmath>
#include <exception>
#include <sstream>

#include <lcm/lcm_coretypes.h>

#include "arbor_slam/core/information.h"

namespace arbor {
namespace {

// Byte offsets of the length fields that precede variable arrays/strings, after the 8-byte
// hash (fixed by the field order of io/lcm/*.lcm; tests/lcm_messages_test.cc checks them).
constexpr int kEdgeInformationSizeOffset = 8 + 5 * 8 + 1 + 3 * 8 + 4 * 8;             // 105
constexpr int kPriorInformationSizeOffset = 8 + 4 * 8 + 1 + 1 + 2 * (3 * 8 + 4 * 8);  // 154
constexpr int kEstimateNumPosesOffset = 8 + 4 * 8 + 1 + 1 + 4 + 8;                    // 54
constexpr int kEstimateBytesPerPose = 8 + 3 * 8 + 4 * 8;
constexpr int kCommandPathLengthOffset = 8 + 8 + 1;             // 17
constexpr int kStatusNumReasonsOffset = 8 + 9 * 8 + 4 + 4 + 8;  // 96
constexpr int kMaxInformationSize = 64;
// status_t's fixed fields between reason_count and batch_winner (latency_window … batch_max_
// rotation_diff), and between batch_winner and last_command_result (batch_margin …
// last_command_seq); tests/lcm_messages_test.cc checks them against an encoded message.
constexpr int kStatusBytesBeforeBatchWinner = 4 + 3 * 8 + 4 + 3 * 8 + 3 * 4 + 8 + 4 + 6 * 8;
constexpr int kStatusBytesBeforeLastCommandResult =
    8 + 1 + 4 + 8 + 8 + 1 + 6 * 8 + 4 + 6 * 8 + 2 * 4 + 2 * 8;

bool readInt32(const void* data, int size, int offset, std::int32_t* value) {
  if (offset + 4 > size) return false;
  return __int32_t_decode_array(data, offset, size - offset, value, 1) == 4;
}

void setDetail(std::string* detail, const std::string& text) {
  if (detail) *detail = text;
}

// kTruncated for bytes that end before the length field at `offset` (what of `type` it is).
MessageProblem truncatedBefore(int size, int offset, const char* field, const char* type,
                               std::string* detail) {
  setDetail(detail, std::to_string(size) + " bytes end before " + field + " (bytes " +
                        std::to_string(offset) + " to " + std::to_string(offset + 3) + ") of " +
                        type);
  return MessageProblem::kTruncated;
}

// Checks the variable-length fields of M before its generated decoder allocates from them.
// Returns kNone, kTruncated (a length field lies beyond the end) or kMalformed.
template <class M>
MessageProblem precheck(const void*, int, std::string*) {
  return MessageProblem::kNone;
}

// The information_size of edge_t or prior_t at `offset`, checked before the generated decoder
// allocates that many doubles.
MessageProblem precheckInformationSize(const void* data, int size, int offset, const char* type,
                                       std::string* detail) {
  std::int32_t n = 0;
  if (!readInt32(data, size, offset, &n)) {
    setDetail(detail, std::to_string(size) + " bytes, " + type + " needs at least " +
                          std::to_string(offset + 4));
    return MessageProblem::kTruncated;
  }
  if (n < 0 || n > kMaxInformationSize) {
    setDetail(detail, "information_size " + std::to_string(n) + " is out of range");
    return MessageProblem::kMalformed;
  }
  return MessageProblem::kNone;
}

template <>
MessageProblem precheck<edge_t>(const void* data, int size, std::string* detail) {
  return precheckInformationSize(data, size, kEdgeInformationSizeOffset, "an edge_t", detail);
}

template <>
MessageProblem precheck<edge_v1_t>(const void* data, int size, std::string* detail) {
  return precheckInformationSize(data, size, kEdgeInformationSizeOffset, "an edge_v1_t", detail);
}

template <>
MessageProblem precheck<prior_t>(const void* data, int size, std::string* detail) {
  return precheckInformationSize(data, size, kPriorInformationSizeOffset, "a prior_t", detail);
}

template <>
MessageProblem precheck<estimate_t>(const void* data, int size, std::string* detail) {
  std::int32_t n = 0;
  if (!readInt32(data, size, kEstimateNumPosesOffset, &n)) {
    return truncatedBefore(size, kEstimateNumPosesOffset, "num_poses", "an estimate_t", detail);
  }
  if (n < 0 ||
      static_cast<std::int64_t>(n) * kEstimateBytesPerPose > size - kEstimateNumPosesOffset - 4) {
    setDetail(detail, "num_poses " + std::to_string(n) + " does not fit " + std::to_string(size) +
                          " bytes");
    return n < 0 ? MessageProblem::kMalformed : MessageProblem::kTruncated;
  }
  return MessageProblem::kNone;
}

// A string's length field at `offset` (LCM counts the NUL): at least 1 and no longer than the
// bytes left, checked before the generated decoder takes length − 1 (a signed overflow for
// −2³¹) or allocates from it. `*next` is the offset after the string.
MessageProblem precheckString(const void* data, int size, int offset, const std::string& field,
                              const char* type, std::string* detail, int* next = nullptr) {
  std::int32_t n = 0;
  if (!readInt32(data, size, offset, &n)) {
    return truncatedBefore(size, offset, (field + "'s length").c_str(), type, detail);
  }
  if (n < 1) {
    setDetail(detail, field + " length " + std::to_string(n) + " at byte " +
                          std::to_string(offset) + " (must count the NUL)");
    return MessageProblem::kMalformed;
  }
  if (n > size - offset - 4) {
    setDetail(detail, field + " length " + std::to_string(n) + " at byte " +
                          std::to_string(offset) + " runs past the end of " + std::to_string(size) +
                          " bytes");
    return MessageProblem::kTruncated;
  }
  if (next) *next = offset + 4 + n;
  return MessageProblem::kNone;
}

template <>
MessageProblem precheck<command_t>(const void* data, int size, std::string* detail) {
  return precheckString(data, size, kCommandPathLengthOffset, "path", "a command_t", detail);
}

// An array of `count` elements of `bytes` each must fit the `size − offset` bytes left.
MessageProblem precheckCount(std::int32_t count, int bytes, int size, int offset,
                             const std::string& what, std::string* detail) {
  if (count < 0 || static_cast<std::int64_t>(count) * bytes > size - offset) {
    setDetail(detail, what + " " + std::to_string(count) + " does not fit " + std::to_string(size) +
                          " bytes");
    return count < 0 ? MessageProblem::kMalformed : MessageProblem::kTruncated;
  }
  return MessageProblem::kNone;
}

template <>
MessageProblem precheck<covariance_t>(const void* data, int size, std::string* detail) {
  constexpr int kNumIdsOffset = 8 + 8 + 8;  // hash, utime, request
  std::int32_t n = 0, dim = 0;
  if (!readInt32(data, size, kNumIdsOffset, &n)) {
    return truncatedBefore(size, kNumIdsOffset, "num_ids", "a covariance_t", detail);
  }
  MessageProblem p = precheckCount(n, 8, size, kNumIdsOffset + 4, "num_ids", detail);
  if (p != MessageProblem::kNone) return p;
  const int dim_offset = kNumIdsOffset + 4 + 8 * n + 8;  // ids, update
  if (!readInt32(data, size, dim_offset, &dim)) {
    return truncatedBefore(size, dim_offset, "dim", "a covariance_t", detail);
  }
  if (dim < 0 || dim > 1 << 12) {
    setDetail(detail, "dim " + std::to_string(dim) + " is out of range");
    return MessageProblem::kMalformed;
  }
  p = precheckCount(dim * dim, 8, size, dim_offset + 4, "dim × dim", detail);
  if (p != MessageProblem::kNone) return p;
  return precheckString(data, size, dim_offset + 4 + 8 * dim * dim, "error", "a covariance_t",
                        detail);
}

template <>
MessageProblem precheck<status_t>(const void* data, int size, std::string* detail) {
  std::int32_t n = 0;
  if (!readInt32(data, size, kStatusNumReasonsOffset, &n)) {
    return truncatedBefore(size, kStatusNumReasonsOffset, "num_reasons", "a status_t", detail);
  }
  // Each reason takes at least 5 bytes (length + NUL) plus an 8-byte count.
  if (n < 0 || static_cast<std::int64_t>(n) * 13 > size - kStatusNumReasonsOffset - 4) {
    setDetail(detail, "num_reasons " + std::to_string(n) + " is out of range");
    return n < 0 ? MessageProblem::kMalformed : MessageProblem::kTruncated;
  }
  int at = kStatusNumReasonsOffset + 4;
  for (std::int32_t k = 0; k < n; ++k) {
    const MessageProblem p = precheckString(data, size, at, "reason[" + std::to_string(k) + "]",
                                            "a status_t", detail, &at);
    if (p != MessageProblem::kNone) return p;
  }
  // reason_count, then the fixed fields up to batch_winner, and from it to last_command_result.
  at += 8 * n + kStatusBytesBeforeBatchWinner;
  MessageProblem p = precheckString(data, size, at, "batch_winner", "a status_t", detail, &at);
  if (p != MessageProblem::kNone) return p;
  at += kStatusBytesBeforeLastCommandResult;
  return precheckString(data, size, at, "last_command_result", "a status_t", detail);
}

// The types with string fields. LCM's generated decoder takes a string's last byte for its NUL
// without looking at it and keeps any NUL before it, so "out.g2o\0-rf" would be read as a string
// that a C API (and LCM's own encoder, which uses strlen) sees as "out.g2o".
template <class M>
constexpr bool kHasStrings = false;
template <>
constexpr bool kHasStrings<command_t> = true;
template <>
constexpr bool kHasStrings<covariance_t> = true;
template <>
constexpr bool kHasStrings<status_t> = true;

// A decoded message with strings must encode back to exactly its bytes: every string ends in its
// NUL and holds none before it. kMalformed (the first byte that differs, its value) otherwise.
template <class M>
MessageProblem checkStrings(const M& message, const void* data, int size, std::string* detail) {
  if constexpr (!kHasStrings<M>) {
    return MessageProblem::kNone;
  } else {
    std::vector<std::uint8_t> again(static_cast<size_t>(size), 0);
    const int n = message.encode(again.data(), 0, size);
    const auto* bytes = static_cast<const std::uint8_t*>(data);
    int at = 0;
    while (at < size && at < n && again[static_cast<size_t>(at)] == bytes[at]) ++at;
    if (n == size && at == size) return MessageProblem::kNone;
    std::ostringstream os;
    os << M::getTypeName() << ": a string without its terminating NUL or with a NUL inside it";
    if (at < size) os << " (byte " << at << " reads 0x" << std::hex << int{bytes[at]} << ")";
    setDetail(detail, os.str());
    return MessageProblem::kMalformed;
  }
}

template <>
MessageProblem precheck<resend_t>(const void* data, int size, std::string* detail) {
  constexpr int kNumRangesOffset = 8 + 8 + 1 + 1 + 3 * 8;  // 42
  std::int16_t n = 0;
  if (kNumRangesOffset + 2 > size ||
      __int16_t_decode_array(data, kNumRangesOffset, size - kNumRangesOffset, &n, 1) != 2) {
    setDetail(detail, std::to_string(size) + " bytes, a resend_t needs at least " +
                          std::to_string(kNumRangesOffset + 2));
    return MessageProblem::kTruncated;
  }
  if (n < 0 || n > kMaxResendRanges) {
    setDetail(detail, "num_ranges " + std::to_string(n) + " is not in 0.." +
                          std::to_string(kMaxResendRanges));
    return MessageProblem::kMalformed;
  }
  return precheckCount(2 * n, 8, size, kNumRangesOffset + 2, "2 × num_ranges", detail);
}

bool allFinite(const double* v, int n) {
  for (int k = 0; k < n; ++k) {
    if (!std::isfinite(v[k])) return false;
  }
  return true;
}

// Ω from its upper triangle, row by row (as edge_t and prior_t carry it).
template <int n>
Eigen::Matrix<double, n, n> fromUpperTriangle(const std::vector<double>& entries) {
  Eigen::Matrix<double, n, n> omega;
  int k = 0;
  for (int r = 0; r < n; ++r) {
    for (int c = r; c < n; ++c, ++k) omega(r, c) = omega(c, r) = entries[k];
  }
  return omega;
}

template <int n>
void toUpperTriangle(const Eigen::Matrix<double, n, n>& omega, std::vector<double>* entries) {
  entries->clear();
  entries->reserve(n * (n + 1) / 2);
  for (int r = 0; r < n; ++r) {
    for (int c = r; c < n; ++c) entries->push_back(omega(r, c));
  }
}

// A pose from the fields translation[3], rotation[4] (finite, checked before): 2D needs
// translation[2] = rotation[1..3] = 0, 3D a unit quaternion (to 1e-3); no translation component
// beyond kMaxTranslation. `what` names the pose in the detail ("a 2D edge", "the offset", ...).
template <class G>
MessageProblem poseFromCheckedFields(const double translation[3], const double rotation[4],
                                     const std::string& what, G* pose, std::string* detail) {
  if constexpr (G::kDim == 2) {
    if (translation[2] != 0 || rotation[1] != 0 || rotation[2] != 0 || rotation[3] != 0) {
      *detail = what + " has nonzero translation[2] or rotation[1..3] in 2D";
      return MessageProblem::kDim;
    }
    *pose = SE2(translation[0], translation[1], rotation[0]);
  } else {
    const Eigen::Quaterniond q(rotation[0], rotation[1], rotation[2], rotation[3]);
    const double norm = q.norm();
    if (std::abs(norm - 1.0) > 1e-3) {
      std::ostringstream os;
      os << what << ": quaternion norm " << norm << " is not 1";
      *detail = os.str();
      return MessageProblem::kRotation;
    }
    *pose = SE3(q, Eigen::Vector3d(translation[0], translation[1], translation[2]));
  }
  const std::string far = translationProblem(*pose);
  if (!far.empty()) {
    *detail = what + ": " + far;
    return MessageProblem::kMagnitude;
  }
  return MessageProblem::kNone;
}

template <class G>
EdgeDecoding toStreamEdge(const edge_t& m) {
  constexpr int d = G::kDoF;
  EdgeDecoding out;
  StreamEdge<G> e;
  e.utime = m.utime;
  e.sender = m.sender;
  e.seq = m.seq;
  e.from = m.from_id;
  e.to = m.to_id;
  out.problem = poseFromCheckedFields(m.translation, m.rotation,
                                      G::kDim == 2 ? "a 2D edge" : "the edge", &e.z, &out.detail);
  if (!out.ok()) return out;
  e.omega = fromUpperTriangle<d>(m.information);
  const std::string problem = informationProblem(e.omega);
  if (!problem.empty()) {
    out.problem = MessageProblem::kInformation;
    out.detail = "information matrix " + problem;
    return out;
  }
  if (!edgeTrustFromField(m.trust, &e.trust, &out.detail) ||
      !edgeKernelFromField(m.kernel, &e.kernel, &out.detail)) {
    out.problem = MessageProblem::kTrust;
    return out;
  }
  out.edge = e;
  return out;
}

// The older layout as the current one: trust and kernel DEFAULT (what it meant then).
edge_t fromV1(const edge_v1_t& v1) {
  edge_t m;
  m.utime = v1.utime;
  m.sender = v1.sender;
  m.seq = v1.seq;
  m.from_id = v1.from_id;
  m.to_id = v1.to_id;
  m.dim = v1.dim;
  for (int k = 0; k < 3; ++k) m.translation[k] = v1.translation[k];
  for (int k = 0; k < 4; ++k) m.rotation[k] = v1.rotation[k];
  m.information_size = v1.information_size;
  m.information = v1.information;
  m.trust = edge_t::TRUST_DEFAULT;
  m.kernel = edge_t::KERNEL_DEFAULT;
  return m;
}

std::int64_t leadingHash(const void* data, int size) {
  std::int64_t hash = 0;
  if (data != nullptr && size >= 8) __int64_t_decode_array(data, 0, size, &hash, 1);
  return hash;
}

template <class G>
PriorDecoding toStreamPrior(const prior_t& m) {
  PriorDecoding out;
  auto fail = [&](MessageProblem p, const std::string& what) {
    out.problem = p;
    out.detail = what;
    return out;
  };
  if (m.kind == prior_t::POSE) {
    StreamPosePrior<G> prior;
    prior.utime = m.utime;
    prior.sender = m.sender;
    prior.seq = m.seq;
    prior.id = m.id;
    out.problem =
        poseFromCheckedFields(m.translation, m.rotation, "the pose prior", &prior.z, &out.detail);
    if (!out.ok()) return out;
    out.problem = poseFromCheckedFields(m.offset_translation, m.offset_rotation,
                                        "the pose prior's offset", &prior.offset, &out.detail);
    if (!out.ok()) return out;
    prior.omega = fromUpperTriangle<G::kDoF>(m.information);
    const std::string problem = informationProblem(prior.omega);
    if (!problem.empty())
      return fail(MessageProblem::kInformation, "information matrix " + problem);
    out.prior = prior;
    return out;
  }
  StreamPositionPrior<G> prior;
  prior.utime = m.utime;
  prior.sender = m.sender;
  prior.seq = m.seq;
  prior.id = m.id;
  if (G::kDim == 2 && m.translation[2] != 0)
    return fail(MessageProblem::kDim, "a 2D position prior has nonzero translation[2]");
  for (int k = 0; k < G::kDim; ++k) prior.p[k] = m.translation[k];
  const double largest = prior.p.cwiseAbs().maxCoeff();
  if (largest > kMaxTranslation) {
    std::ostringstream os;
    os << "the position prior: component of magnitude " << largest
       << " beyond the largest accepted (" << kMaxTranslation << ")";
    return fail(MessageProblem::kMagnitude, os.str());
  }
  prior.omega = fromUpperTriangle<G::kDim>(m.information);
  const std::string problem = informationProblem(prior.omega);
  if (!problem.empty()) return fail(MessageProblem::kInformation, "information matrix " + problem);
  out.prior = prior;
  return out;
}

}  // namespace

const char* toString(MessageProblem problem) {
  switch (problem) {
    case MessageProblem::kNone:
      return "ok";
    case MessageProblem::kTruncated:
      return "truncated";
    case MessageProblem::kTrailingBytes:
      return "trailing bytes";
    case MessageProblem::kTypeHash:
      return "type hash";
    case MessageProblem::kMalformed:
      return "malformed";
    case MessageProblem::kDim:
      return "dim";
    case MessageProblem::kNotFinite:
      return "not finite";
    case MessageProblem::kRotation:
      return "rotation";
    case MessageProblem::kInformation:
      return "information";
    case MessageProblem::kSelfLoop:
      return "self-loop";
    case MessageProblem::kId:
      return "id";
    case MessageProblem::kSeq:
      return "seq";
    case MessageProblem::kMagnitude:
      return "magnitude";
    case MessageProblem::kKind:
      return "kind";
    case MessageProblem::kTrust:
      return "trust";
  }
  return "unknown";
}

template <class M>
MessageProblem decodeMessage(const void* data, int size, M* out, std::string* detail) {
  if (data == nullptr || size < 8) {
    setDetail(detail, std::to_string(size) + " bytes, shorter than a type hash");
    return MessageProblem::kTruncated;
  }
  std::int64_t hash = 0;
  __int64_t_decode_array(data, 0, size, &hash, 1);
  if (hash != M::getHash()) {
    std::ostringstream os;
    os << "type hash 0x" << std::hex << static_cast<std::uint64_t>(hash) << " is not "
       << M::getTypeName() << "'s 0x" << static_cast<std::uint64_t>(M::getHash());
    setDetail(detail, os.str());
    return MessageProblem::kTypeHash;
  }
  const MessageProblem pre = precheck<M>(data, size, detail);
  if (pre != MessageProblem::kNone) return pre;
  int used = -1;
  try {
    used = out->decode(data, 0, size);
  } catch (const std::exception& e) {
    setDetail(detail, std::string("malformed: ") + e.what());
    return MessageProblem::kMalformed;
  }
  if (used < 0) {
    setDetail(detail, std::to_string(size) + " bytes end inside a " + M::getTypeName());
    return MessageProblem::kTruncated;
  }
  if (used != size) {
    setDetail(detail,
              std::to_string(size - used) + " bytes after the end of a " + M::getTypeName());
    return MessageProblem::kTrailingBytes;
  }
  return checkStrings(*out, data, size, detail);
}

bool isEdgeMessage(const void* data, int size) {
  const std::int64_t hash = leadingHash(data, size);
  return hash == edge_t::getHash() || hash == edge_v1_t::getHash();
}

bool edgeTrustFromField(std::int8_t field, EdgeTrust* trust, std::string* detail) {
  switch (field) {
    case edge_t::TRUST_DEFAULT:
      *trust = EdgeTrust::kByRule;
      return true;
    case edge_t::TRUST_TRUSTED:
      *trust = EdgeTrust::kTrusted;
      return true;
    case edge_t::TRUST_ROBUST:
      *trust = EdgeTrust::kRobust;
      return true;
  }
  setDetail(detail, "trust " + std::to_string(field) +
                        " is not TRUST_DEFAULT (0), TRUST_TRUSTED (1) or TRUST_ROBUST (2)");
  return false;
}

bool edgeKernelFromField(std::int8_t field, KernelKind* kernel, std::string* detail) {
  switch (field) {
    case edge_t::KERNEL_DEFAULT:
      *kernel = KernelKind::kNone;
      return true;
    case edge_t::KERNEL_TLS:
      *kernel = KernelKind::kTruncatedLeastSquares;
      return true;
    case edge_t::KERNEL_GM:
      *kernel = KernelKind::kGemanMcClure;
      return true;
    case edge_t::KERNEL_CAUCHY:
      *kernel = KernelKind::kCauchy;
      return true;
    case edge_t::KERNEL_HUBER:
      *kernel = KernelKind::kHuber;
      return true;
  }
  setDetail(detail, "kernel " + std::to_string(field) +
                        " is not KERNEL_DEFAULT (0), KERNEL_TLS (1), KERNEL_GM (2), "
                        "KERNEL_CAUCHY (3) or KERNEL_HUBER (4)");
  return false;
}

ResendDecoding decodeResend(const void* data, int size) {
  ResendDecoding out;
  resend_t m;
  out.problem = decodeMessage(data, size, &m, &out.detail);
  if (!out.ok()) return out;
  const auto fail = [&](MessageProblem p, const std::string& detail) {
    out.problem = p;
    out.detail = detail;
    return out;
  };
  if (m.kind != resend_t::REQUEST && m.kind != resend_t::WINDOW) {
    return fail(MessageProblem::kKind,
                "kind " + std::to_string(m.kind) + " is not REQUEST (1) or WINDOW (2)");
  }
  if (m.stream != resend_t::EDGES && m.stream != resend_t::PRIORS) {
    return fail(MessageProblem::kKind,
                "stream " + std::to_string(m.stream) + " is not EDGES (1) or PRIORS (2)");
  }
  if (m.settled < 0 || m.highest < m.settled) {
    return fail(MessageProblem::kSeq, "settled " + std::to_string(m.settled) + " and highest " +
                                          std::to_string(m.highest) +
                                          " are not 0 <= settled <= highest");
  }
  if (m.kind == resend_t::WINDOW && m.num_ranges != 0) {
    return fail(MessageProblem::kMalformed,
                "a WINDOW answer carries no ranges, not " + std::to_string(m.num_ranges));
  }
  std::int64_t floor = m.settled;  // each range starts above the previous one's end
  for (int k = 0; k < m.num_ranges; ++k) {
    const std::int64_t first = m.first[static_cast<size_t>(k)];
    const std::int64_t last = m.last[static_cast<size_t>(k)];
    if (first <= floor || last < first || last >= m.highest) {
      return fail(MessageProblem::kSeq,
                  "range " + std::to_string(k) + " (" + std::to_string(first) + ".." +
                      std::to_string(last) + ") is not ascending inside " +
                      std::to_string(floor + 1) + ".." + std::to_string(m.highest - 1));
    }
    floor = last;
    out.message.missing.emplace_back(first, last);
  }
  out.message.request = m.kind == resend_t::REQUEST;
  out.message.priors = m.stream == resend_t::PRIORS;
  out.message.utime = m.utime;
  out.message.sender = m.sender;
  out.message.settled = m.settled;
  out.message.highest = m.highest;
  return out;
}

resend_t makeResendMessage(const ResendMessage& r) {
  if (r.missing.size() > static_cast<size_t>(kMaxResendRanges)) {
    throw std::invalid_argument("makeResendMessage: " + std::to_string(r.missing.size()) +
                                " ranges, more than " + std::to_string(kMaxResendRanges));
  }
  resend_t m;
  m.utime = r.utime;
  m.kind = r.request ? resend_t::REQUEST : resend_t::WINDOW;
  m.stream = r.priors ? resend_t::PRIORS : resend_t::EDGES;
  m.sender = r.sender;
  m.settled = r.settled;
  m.highest = r.highest;
  m.num_ranges = static_cast<std::int16_t>(r.missing.size());
  for (const auto& [first, last] : r.missing) {
    m.first.push_back(first);
    m.last.push_back(last);
  }
  return m;
}

std::vector<Key> covarianceIds(const std::string& path) {
  std::istringstream in(path);
  std::vector<Key> ids;
  std::string word;
  while (in >> word) {
    Key id = -1;
    const auto end = std::from_chars(word.data(), word.data() + word.size(), id);
    if (end.ec != std::errc() || end.ptr != word.data() + word.size() || id < 0)
      throw std::invalid_argument("covariance: '" + word + "' in '" + path + "' is not a pose id");
    ids.push_back(id);
  }
  if (ids.size() != 1 && ids.size() != 2)
    throw std::invalid_argument("covariance needs 1 or 2 pose ids, not " +
                                std::to_string(ids.size()) + " ('" + path + "')");
  return ids;
}

EdgeDecoding decodeEdge(const void* data, int size) {
  EdgeDecoding out;
  edge_t m;
  if (leadingHash(data, size) == edge_v1_t::getHash()) {
    edge_v1_t v1;
    out.problem = decodeMessage(data, size, &v1, &out.detail);
    if (!out.ok()) return out;
    m = fromV1(v1);
  } else {
    out.problem = decodeMessage(data, size, &m, &out.detail);
    if (!out.ok()) return out;
  }
  auto fail = [&](MessageProblem p, const std::string& what) {
    out.problem = p;
    out.detail = what;
    return out;
  };
  if (m.dim != 2 && m.dim != 3)
    return fail(MessageProblem::kDim, "dim " + std::to_string(m.dim) + " is not 2 or 3");
  const int expected = m.dim == 2 ? 6 : 21;
  if (m.information_size != expected) {
    return fail(MessageProblem::kDim, "dim " + std::to_string(m.dim) + " needs " +
                                          std::to_string(expected) + " information entries, got " +
                                          std::to_string(m.information_size));
  }
  if (!allFinite(m.translation, 3))
    return fail(MessageProblem::kNotFinite, "translation is not finite");
  if (!allFinite(m.rotation, 4)) return fail(MessageProblem::kNotFinite, "rotation is not finite");
  if (!allFinite(m.information.data(), m.information_size)) {
    return fail(MessageProblem::kNotFinite, "information is not finite");
  }
  if (m.from_id < 0 || m.to_id < 0) {
    return fail(MessageProblem::kId,
                "negative pose id " + std::to_string(std::min(m.from_id, m.to_id)));
  }
  if (m.from_id == m.to_id) {
    return fail(MessageProblem::kSelfLoop, "self-loop at pose " + std::to_string(m.from_id));
  }
  if (m.seq < 1) return fail(MessageProblem::kSeq, "seq " + std::to_string(m.seq) + " is not >= 1");
  return m.dim == 2 ? toStreamEdge<SE2>(m) : toStreamEdge<SE3>(m);
}

PriorDecoding decodePrior(const void* data, int size) {
  PriorDecoding out;
  prior_t m;
  out.problem = decodeMessage(data, size, &m, &out.detail);
  if (!out.ok()) return out;
  auto fail = [&](MessageProblem p, const std::string& what) {
    out.problem = p;
    out.detail = what;
    return out;
  };
  const bool pose = m.kind == prior_t::POSE;
  if (!pose && m.kind != prior_t::POSITION) {
    return fail(MessageProblem::kKind,
                "kind " + std::to_string(m.kind) + " is not POSE (1) or POSITION (2)");
  }
  if (m.dim != 2 && m.dim != 3)
    return fail(MessageProblem::kDim, "dim " + std::to_string(m.dim) + " is not 2 or 3");
  const int n = pose ? (m.dim == 2 ? 3 : 6) : m.dim;  // Ω is n×n
  const int expected = n * (n + 1) / 2;
  if (m.information_size != expected) {
    return fail(MessageProblem::kDim, "a " + std::to_string(m.dim) + "D " +
                                          (pose ? "pose" : "position") + " prior needs " +
                                          std::to_string(expected) + " information entries, got " +
                                          std::to_string(m.information_size));
  }
  if (!allFinite(m.translation, 3))
    return fail(MessageProblem::kNotFinite, "translation is not finite");
  if (!allFinite(m.rotation, 4)) return fail(MessageProblem::kNotFinite, "rotation is not finite");
  if (!allFinite(m.offset_translation, 3) || !allFinite(m.offset_rotation, 4))
    return fail(MessageProblem::kNotFinite, "offset is not finite");
  if (!allFinite(m.information.data(), m.information_size)) {
    return fail(MessageProblem::kNotFinite, "information is not finite");
  }
  if (m.id < 0) return fail(MessageProblem::kId, "negative pose id " + std::to_string(m.id));
  if (m.seq < 1) return fail(MessageProblem::kSeq, "seq " + std::to_string(m.seq) + " is not >= 1");
  if (!pose) {
    bool unused_zero = true;
    for (int k = 0; k < 4; ++k)
      unused_zero = unused_zero && m.rotation[k] == 0 && m.offset_rotation[k] == 0;
    for (int k = 0; k < 3; ++k) unused_zero = unused_zero && m.offset_translation[k] == 0;
    if (!unused_zero) {
      return fail(MessageProblem::kKind,
                  "a position prior has a nonzero rotation or offset (both must be 0; a prior "
                  "on the whole pose is kind POSE)");
    }
  }
  return m.dim == 2 ? toStreamPrior<SE2>(m) : toStreamPrior<SE3>(m);
}

EdgeCommandDecoding decodeEdgeCommand(const void* data, int size) {
  EdgeCommandDecoding out;
  edge_command_t m;
  out.problem = decodeMessage(data, size, &m, &out.detail);
  if (!out.ok()) return out;
  auto fail = [&](MessageProblem p, const std::string& what) {
    out.problem = p;
    out.detail = what;
    return out;
  };
  if (m.command != edge_command_t::DISABLE_EDGE && m.command != edge_command_t::ENABLE_EDGE) {
    return fail(MessageProblem::kKind, "command " + std::to_string(m.command) +
                                           " is not DISABLE_EDGE (1) or ENABLE_EDGE (2)");
  }
  if (m.from_id < 0)
    return fail(MessageProblem::kId, "from_id " + std::to_string(m.from_id) + " is negative");
  if (m.to_id < 0)
    return fail(MessageProblem::kId, "to_id " + std::to_string(m.to_id) + " is negative");
  if (m.from_id == m.to_id) {
    return fail(MessageProblem::kSelfLoop,
                "from_id and to_id are both " + std::to_string(m.from_id) + ": no such edge");
  }
  if (m.seq < 1) return fail(MessageProblem::kSeq, "seq " + std::to_string(m.seq) + " is not >= 1");
  StreamEdgeCommand& c = out.command;
  c.utime = m.utime;
  c.sender = m.sender;
  c.seq = m.seq;
  c.kind = m.command == edge_command_t::DISABLE_EDGE ? StreamEdgeCommand::Kind::kDisable
                                                     : StreamEdgeCommand::Kind::kEnable;
  c.from = m.from_id;
  c.to = m.to_id;
  return out;
}

edge_command_t makeEdgeCommandMessage(const StreamEdgeCommand& command) {
  edge_command_t m;
  m.utime = command.utime;
  m.sender = command.sender;
  m.seq = command.seq;
  m.command = command.kind == StreamEdgeCommand::Kind::kDisable ? edge_command_t::DISABLE_EDGE
                                                                : edge_command_t::ENABLE_EDGE;
  m.from_id = command.from;
  m.to_id = command.to;
  return m;
}

template <class G>
edge_t makeEdgeMessage(const StreamEdge<G>& edge) {
  constexpr int d = G::kDoF;
  edge_t m;
  m.utime = edge.utime;
  m.sender = edge.sender;
  m.seq = edge.seq;
  m.from_id = edge.from;
  m.to_id = edge.to;
  m.dim = G::kDim;
  poseToFields(edge.z, m.translation, m.rotation);
  m.information_size = d * (d + 1) / 2;
  m.information.reserve(m.information_size);
  for (int r = 0; r < d; ++r) {
    for (int c = r; c < d; ++c) m.information.push_back(edge.omega(r, c));
  }
  m.trust = edge.trust == EdgeTrust::kTrusted  ? edge_t::TRUST_TRUSTED
            : edge.trust == EdgeTrust::kRobust ? edge_t::TRUST_ROBUST
                                               : edge_t::TRUST_DEFAULT;
  switch (edge.kernel) {
    case KernelKind::kTruncatedLeastSquares:
      m.kernel = edge_t::KERNEL_TLS;
      break;
    case KernelKind::kGemanMcClure:
      m.kernel = edge_t::KERNEL_GM;
      break;
    case KernelKind::kCauchy:
      m.kernel = edge_t::KERNEL_CAUCHY;
      break;
    case KernelKind::kHuber:
      m.kernel = edge_t::KERNEL_HUBER;
      break;
    default:
      m.kernel = edge_t::KERNEL_DEFAULT;
  }
  return m;
}

template <class G>
edge_v1_t makeEdgeV1Message(const StreamEdge<G>& edge) {
  const edge_t m = makeEdgeMessage(edge);
  edge_v1_t v1;
  v1.utime = m.utime;
  v1.sender = m.sender;
  v1.seq = m.seq;
  v1.from_id = m.from_id;
  v1.to_id = m.to_id;
  v1.dim = m.dim;
  for (int k = 0; k < 3; ++k) v1.translation[k] = m.translation[k];
  for (int k = 0; k < 4; ++k) v1.rotation[k] = m.rotation[k];
  v1.information_size = m.information_size;
  v1.information = m.information;
  return v1;
}

template <class G>
prior_t makePriorMessage(const StreamPosePrior<G>& prior) {
  prior_t m;
  m.utime = prior.utime;
  m.sender = prior.sender;
  m.seq = prior.seq;
  m.id = prior.id;
  m.kind = prior_t::POSE;
  m.dim = G::kDim;
  poseToFields(prior.z, m.translation, m.rotation);
  poseToFields(prior.offset, m.offset_translation, m.offset_rotation);
  toUpperTriangle<G::kDoF>(prior.omega, &m.information);
  m.information_size = static_cast<std::int32_t>(m.information.size());
  return m;
}

template <class G>
prior_t makePriorMessage(const StreamPositionPrior<G>& prior) {
  prior_t m;
  m.utime = prior.utime;
  m.sender = prior.sender;
  m.seq = prior.seq;
  m.id = prior.id;
  m.kind = prior_t::POSITION;
  m.dim = G::kDim;
  for (int k = 0; k < 3; ++k) m.translation[k] = k < G::kDim ? prior.p[k] : 0.0;
  for (int k = 0; k < 4; ++k) m.rotation[k] = m.offset_rotation[k] = 0;
  for (int k = 0; k < 3; ++k) m.offset_translation[k] = 0;
  toUpperTriangle<G::kDim>(prior.omega, &m.information);
  m.information_size = static_cast<std::int32_t>(m.information.size());
  return m;
}

template edge_t makeEdgeMessage(const StreamEdge<SE2>&);
template edge_t makeEdgeMessage(const StreamEdge<SE3>&);
template edge_v1_t makeEdgeV1Message(const StreamEdge<SE2>&);
template edge_v1_t makeEdgeV1Message(const StreamEdge<SE3>&);
template prior_t makePriorMessage(const StreamPosePrior<SE2>&);
template prior_t makePriorMessage(const StreamPosePrior<SE3>&);
template prior_t makePriorMessage(const StreamPositionPrior<SE2>&);
template prior_t makePriorMessage(const StreamPositionPrior<SE3>&);
template MessageProblem decodeMessage(const void*, int, estimate_t*, std::string*);
template MessageProblem decodeMessage(const void*, int, status_t*, std::string*);
template MessageProblem decodeMessage(const void*, int, command_t*, std::string*);
template MessageProblem decodeMessage(const void*, int, covariance_t*, std::string*);
template MessageProblem decodeMessage(const void*, int, journal_mark_t*, std::string*);
template MessageProblem decodeMessage(const void*, int, edge_t*, std::string*);
template MessageProblem decodeMessage(const void*, int, edge_v1_t*, std::string*);
template MessageProblem decodeMessage(const void*, int, prior_t*, std::string*);
template MessageProblem decodeMessage(const void*, int, edge_command_t*, std::string*);
template MessageProblem decodeMessage(const void*, int, resend_t*, std::string*);

}  // namespace arbor
