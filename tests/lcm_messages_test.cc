// io/lcm_messages.h and io/lcm_journal.h: checked decoding of edge_t, prior_t and
// edge_command_t (every bad field, truncated bytes, wrong type hash, random corruption) and the
// event-log journal.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <iterator>
#include <limits>
#include <random>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <unistd.h>

#include "arbor_slam/io/lcm_journal.h"
#include "arbor_slam/io/lcm_messages.h"

namespace arbor {
namespace {

StreamEdge<SE2> sampleEdge2() {
  StreamEdge<SE2> e;
  e.utime = 123;
  e.sender = 7;
  e.seq = 42;
  e.from = 3;
  e.to = 4;
  e.z = SE2(1.5, -0.25, 0.3);
  e.omega << 50, 1, 2, 1, 40, 3, 2, 3, 900;
  return e;
}

StreamEdge<SE3> sampleEdge3() {
  StreamEdge<SE3> e;
  e.sender = 1;
  e.seq = 1;
  e.from = 10;
  e.to = 2;
  e.z = SE3(Eigen::Quaterniond(0.9, 0.1, -0.3, 0.2).normalized(), Eigen::Vector3d(1, 2, 3));
  e.omega = Eigen::Matrix<double, 6, 6>::Identity() * 100;
  e.omega(0, 5) = e.omega(5, 0) = 5;
  return e;
}

MessageProblem problemOf(const edge_t& m) {
  const auto bytes = encodeMessage(m);
  return decodeEdge(bytes.data(), static_cast<int>(bytes.size())).problem;
}

TEST(LcmMessages, Edge2RoundTrip) {
  const StreamEdge<SE2> e = sampleEdge2();
  const auto bytes = encodeMessage(makeEdgeMessage(e));
  // The offset of information_size that the decoder pre-checks: 109 + 8 n bytes, then trust
  // and kernel (one byte each).
  EXPECT_EQ(bytes.size(), 111u + 8u * 6u);
  const EdgeDecoding d = decodeEdge(bytes.data(), static_cast<int>(bytes.size()));
  ASSERT_TRUE(d.ok()) << d.detail;
  const auto& got = std::get<StreamEdge<SE2>>(d.edge);
  EXPECT_EQ(got.utime, 123);
  EXPECT_EQ(got.sender, 7);
  EXPECT_EQ(got.seq, 42);
  EXPECT_EQ(got.from, 3);
  EXPECT_EQ(got.to, 4);
  EXPECT_NEAR(got.z.x(), 1.5, 0);
  EXPECT_NEAR(got.z.angle(), 0.3, 1e-15);
  EXPECT_EQ(got.omega, e.omega);
}

TEST(LcmMessages, Edge3RoundTrip) {
  const StreamEdge<SE3> e = sampleEdge3();
  const auto bytes = encodeMessage(makeEdgeMessage(e));
  EXPECT_EQ(bytes.size(), 111u + 8u * 21u);
  const EdgeDecoding d = decodeEdge(bytes.data(), static_cast<int>(bytes.size()));
  ASSERT_TRUE(d.ok()) << d.detail;
  const auto& got = std::get<StreamEdge<SE3>>(d.edge);
  EXPECT_EQ(got.omega, e.omega);
  EXPECT_LT((got.z.translation() - e.z.translation()).norm(), 1e-15);
  EXPECT_NEAR(got.z.quaternion().angularDistance(e.z.quaternion()), 0, 1e-12);
}

TEST(LcmMessages, EdgeTrustAndKernelRoundTrip) {
  StreamEdge<SE2> e = sampleEdge2();
  for (EdgeTrust trust : {EdgeTrust::kByRule, EdgeTrust::kTrusted, EdgeTrust::kRobust}) {
    for (KernelKind kernel : {KernelKind::kNone, KernelKind::kTruncatedLeastSquares,
                              KernelKind::kGemanMcClure, KernelKind::kCauchy, KernelKind::kHuber}) {
      e.trust = trust;
      e.kernel = kernel;
      const auto bytes = encodeMessage(makeEdgeMessage(e));
      const EdgeDecoding d = decodeEdge(bytes.data(), static_cast<int>(bytes.size()));
      ASSERT_TRUE(d.ok()) << d.detail;
      const auto& got = std::get<StreamEdge<SE2>>(d.edge);
      EXPECT_EQ(got.trust, trust) << toString(trust);
      EXPECT_EQ(got.kernel, kernel) << toString(kernel);
    }
  }
}

// The layout before trust and kernel keeps its fingerprint (old journals and publishers) and
// decodes as trust and kernel DEFAULT, with every other field as it was sent.
TEST(LcmMessages, EdgeV1LayoutStillDecodes) {
  EXPECT_EQ(static_cast<std::uint64_t>(edge_v1_t::getHash()), 0xa25c1f74f5f1a4d8ULL);
  EXPECT_NE(edge_v1_t::getHash(), edge_t::getHash());
  StreamEdge<SE2> e = sampleEdge2();
  e.trust = EdgeTrust::kTrusted;  // dropped by the old layout
  const auto bytes = encodeMessage(makeEdgeV1Message(e));
  EXPECT_EQ(bytes.size(), 109u + 8u * 6u);
  EXPECT_TRUE(isEdgeMessage(bytes.data(), static_cast<int>(bytes.size())));
  const EdgeDecoding d = decodeEdge(bytes.data(), static_cast<int>(bytes.size()));
  ASSERT_TRUE(d.ok()) << d.detail;
  const auto& got = std::get<StreamEdge<SE2>>(d.edge);
  EXPECT_EQ(got.trust, EdgeTrust::kByRule);
  EXPECT_EQ(got.kernel, KernelKind::kNone);
  EXPECT_EQ(got.seq, 42);
  EXPECT_EQ(got.from, 3);
  EXPECT_EQ(got.to, 4);
  EXPECT_EQ(got.omega, e.omega);
  EXPECT_NEAR(got.z.angle(), 0.3, 1e-15);
  const auto bytes3 = encodeMessage(makeEdgeV1Message(sampleEdge3()));
  const EdgeDecoding d3 = decodeEdge(bytes3.data(), static_cast<int>(bytes3.size()));
  ASSERT_TRUE(d3.ok()) << d3.detail;
  EXPECT_EQ(std::get<StreamEdge<SE3>>(d3.edge).omega, sampleEdge3().omega);
  for (size_t n = 0; n < bytes.size(); ++n) {
    EXPECT_EQ(decodeEdge(bytes.data(), static_cast<int>(n)).problem, MessageProblem::kTruncated)
        << n;
  }
  // The old layout's validation is the new one's.
  edge_v1_t bad = makeEdgeV1Message(e);
  bad.to_id = bad.from_id;
  const auto bad_bytes = encodeMessage(bad);
  EXPECT_EQ(decodeEdge(bad_bytes.data(), static_cast<int>(bad_bytes.size())).problem,
            MessageProblem::kSelfLoop);
  estimate_t other;
  other.num_poses = 0;
  const auto other_bytes = encodeMessage(other);
  EXPECT_FALSE(isEdgeMessage(other_bytes.data(), static_cast<int>(other_bytes.size())));
}

TEST(LcmMessages, UnknownTrustOrKernelIsRefusedNamingTheValue) {
  const edge_t good = makeEdgeMessage(sampleEdge2());
  auto refused = [&](std::int8_t trust, std::int8_t kernel, const std::string& named) {
    edge_t m = good;
    m.trust = trust;
    m.kernel = kernel;
    const auto bytes = encodeMessage(m);
    const EdgeDecoding d = decodeEdge(bytes.data(), static_cast<int>(bytes.size()));
    EXPECT_EQ(d.problem, MessageProblem::kTrust) << named;
    EXPECT_NE(d.detail.find(named), std::string::npos) << d.detail;
  };
  refused(3, 0, "trust 3");
  refused(-1, 0, "trust -1");
  refused(127, 0, "trust 127");
  refused(0, 5, "kernel 5");
  refused(1, -128, "kernel -128");
  EXPECT_STREQ(toString(MessageProblem::kTrust), "trust");
}

TEST(LcmMessages, EveryTruncationIsRefused) {
  const auto bytes = encodeMessage(makeEdgeMessage(sampleEdge3()));
  for (size_t n = 0; n < bytes.size(); ++n) {
    const EdgeDecoding d = decodeEdge(bytes.data(), static_cast<int>(n));
    EXPECT_EQ(d.problem, MessageProblem::kTruncated) << n << " bytes: " << d.detail;
  }
  auto longer = bytes;
  longer.push_back(0);
  EXPECT_EQ(decodeEdge(longer.data(), static_cast<int>(longer.size())).problem,
            MessageProblem::kTrailingBytes);
}

TEST(LcmMessages, WrongTypeHashIsRefused) {
  estimate_t est;
  est.num_poses = 0;
  est.dim = 2;
  const auto bytes = encodeMessage(est);
  const EdgeDecoding d = decodeEdge(bytes.data(), static_cast<int>(bytes.size()));
  EXPECT_EQ(d.problem, MessageProblem::kTypeHash);
  EXPECT_NE(d.detail.find("edge_t"), std::string::npos) << d.detail;
  auto edge = encodeMessage(makeEdgeMessage(sampleEdge2()));
  edge[3] ^= 0x10;
  EXPECT_EQ(decodeEdge(edge.data(), static_cast<int>(edge.size())).problem,
            MessageProblem::kTypeHash);
}

TEST(LcmMessages, LengthFieldsAreCheckedBeforeAllocation) {
  auto bytes = encodeMessage(makeEdgeMessage(sampleEdge2()));
  // information_size (big-endian int32 at byte 105) set to 2^31-1, then to -1.
  bytes[105] = 0x7f;
  bytes[106] = bytes[107] = bytes[108] = 0xff;
  EXPECT_EQ(decodeEdge(bytes.data(), static_cast<int>(bytes.size())).problem,
            MessageProblem::kMalformed);
  bytes[105] = 0xff;
  EXPECT_EQ(decodeEdge(bytes.data(), static_cast<int>(bytes.size())).problem,
            MessageProblem::kMalformed);

  command_t c;
  c.command = command_t::SNAPSHOT;
  c.path = "x";
  auto cb = encodeMessage(c);
  command_t out;
  ASSERT_EQ(decodeMessage(cb.data(), static_cast<int>(cb.size()), &out), MessageProblem::kNone);
  EXPECT_EQ(out.path, "x");
  cb[17] = cb[18] = cb[19] = cb[20] = 0;  // path length 0 (must include the NUL)
  EXPECT_EQ(decodeMessage(cb.data(), static_cast<int>(cb.size()), &out),
            MessageProblem::kMalformed);
  cb[17] = 0x7f;  // huge
  EXPECT_NE(decodeMessage(cb.data(), static_cast<int>(cb.size()), &out), MessageProblem::kNone);

  estimate_t est;
  est.dim = 2;
  est.num_poses = 2;
  est.ids = {1, 2};
  est.translation.assign(2, std::vector<double>(3, 0.0));
  est.rotation.assign(2, std::vector<double>(4, 0.0));
  auto eb = encodeMessage(est);
  EXPECT_EQ(eb.size(), 58u + 64u * 2u);
  estimate_t back;
  ASSERT_EQ(decodeMessage(eb.data(), static_cast<int>(eb.size()), &back), MessageProblem::kNone);
  EXPECT_EQ(back.ids, est.ids);
  eb[54] = 0x40;  // num_poses ≈ 2^30
  EXPECT_EQ(decodeMessage(eb.data(), static_cast<int>(eb.size()), &back),
            MessageProblem::kTruncated);

  status_t s;
  s.num_reasons = 1;
  s.reason = {"nan"};
  s.reason_count = {3};
  auto sb = encodeMessage(s);
  status_t sback;
  ASSERT_EQ(decodeMessage(sb.data(), static_cast<int>(sb.size()), &sback), MessageProblem::kNone);
  EXPECT_EQ(sback.reason[0], "nan");
  sb[96] = 0x7f;
  EXPECT_NE(decodeMessage(sb.data(), static_cast<int>(sb.size()), &sback), MessageProblem::kNone);
}

// Found by tests/fuzz (corpus regression-* files): LCM's generated decoder takes a string's last
// byte for its NUL unchecked and keeps NULs inside, so a SNAPSHOT path "out.g2o\0-rf" or one
// without its NUL decoded to a string other than what C code and the encoder see; and a message
// cut short before a length field was refused without a detail.
TEST(LcmMessages, AStringWithoutItsNulOrWithANulInsideIsRefusedNamingTheByte) {
  command_t c{};
  c.command = command_t::SNAPSHOT;
  c.path = "out.g2o";
  std::vector<std::uint8_t> bytes = encodeMessage(c);
  command_t out;
  std::string detail;
  ASSERT_EQ(decodeMessage(bytes.data(), static_cast<int>(bytes.size()), &out, &detail),
            MessageProblem::kNone);
  bytes.back() = '!';  // the terminating NUL (byte 28) replaced
  EXPECT_EQ(decodeMessage(bytes.data(), static_cast<int>(bytes.size()), &out, &detail),
            MessageProblem::kMalformed);
  EXPECT_NE(detail.find("command_t"), std::string::npos) << detail;
  EXPECT_NE(detail.find("byte 28 reads 0x21"), std::string::npos) << detail;
  bytes.back() = 0;
  bytes[24] = 0;  // "out.\0g2o": a NUL inside
  EXPECT_EQ(decodeMessage(bytes.data(), static_cast<int>(bytes.size()), &out, &detail),
            MessageProblem::kMalformed);
  EXPECT_NE(detail.find("NUL inside"), std::string::npos) << detail;

  covariance_t cov{};
  cov.error = "unknown pose id";
  std::vector<std::uint8_t> cb = encodeMessage(cov);
  covariance_t cov_out;
  ASSERT_EQ(decodeMessage(cb.data(), static_cast<int>(cb.size()), &cov_out), MessageProblem::kNone);
  cb.back() = 0x80;
  EXPECT_EQ(decodeMessage(cb.data(), static_cast<int>(cb.size()), &cov_out, &detail),
            MessageProblem::kMalformed);

  status_t st{};
  st.num_reasons = 1;
  st.reason = {"nan"};
  st.reason_count = {2};
  std::vector<std::uint8_t> sb = encodeMessage(st);
  status_t st_out;
  ASSERT_EQ(decodeMessage(sb.data(), static_cast<int>(sb.size()), &st_out), MessageProblem::kNone);
  sb[96 + 4 + 4 + 3] = 'x';  // reason[0]'s NUL (after num_reasons, its length and "nan")
  EXPECT_EQ(decodeMessage(sb.data(), static_cast<int>(sb.size()), &st_out, &detail),
            MessageProblem::kMalformed);
}

// Found by tests/fuzz under UBSan: a string length of −2³¹ made LCM's generated decoder compute
// length − 1 in int (a signed overflow); every string length is now checked first.
TEST(LcmMessages, AStringLengthOutOfRangeIsRefusedBeforeTheGeneratedDecoder) {
  covariance_t cov{};
  cov.error = "unknown pose id";
  std::vector<std::uint8_t> cb = encodeMessage(cov);
  const std::size_t error_at = cb.size() - 4 - cov.error.size() - 1;  // its length field
  covariance_t cov_out;
  std::string detail;
  for (std::uint32_t length : {0x80000000u, 0xFFFFFFFFu, 0u}) {
    for (int k = 0; k < 4; ++k)
      cb[error_at + k] = static_cast<std::uint8_t>(length >> (24 - 8 * k));
    EXPECT_EQ(decodeMessage(cb.data(), static_cast<int>(cb.size()), &cov_out, &detail),
              MessageProblem::kMalformed)
        << length;
    EXPECT_NE(detail.find("error length"), std::string::npos) << detail;
  }
  cb[error_at] = 0x7F;  // 2³¹ − 1: past the end
  EXPECT_EQ(decodeMessage(cb.data(), static_cast<int>(cb.size()), &cov_out, &detail),
            MessageProblem::kTruncated);

  status_t st{};
  st.num_reasons = 2;
  st.reason = {"nan", "dim"};
  st.reason_count = {1, 2};
  std::vector<std::uint8_t> sb = encodeMessage(st);
  sb[96 + 4 + 8] = 0x80;  // reason[1]'s length (after num_reasons and "nan" with its length)
  sb[96 + 4 + 9] = sb[96 + 4 + 10] = sb[96 + 4 + 11] = 0;
  status_t st_out;
  EXPECT_EQ(decodeMessage(sb.data(), static_cast<int>(sb.size()), &st_out, &detail),
            MessageProblem::kMalformed);
  EXPECT_NE(detail.find("reason[1] length -2147483648 at byte 108"), std::string::npos) << detail;
}

// Every 4-byte window of a message with strings set to −2³¹ (what a string length of that value
// would be): refused or decoded, never a crash (a string length missed by the prechecks reads
// 2 GiB past the message).
template <class M>
void everyWindowAtIntMin(const M& message) {
  const std::vector<std::uint8_t> bytes = encodeMessage(message);
  for (std::size_t at = 8; at + 4 <= bytes.size(); ++at) {
    std::vector<std::uint8_t> b = bytes;
    b[at] = 0x80;
    b[at + 1] = b[at + 2] = b[at + 3] = 0;
    M out;
    std::string detail;
    const MessageProblem p = decodeMessage(b.data(), static_cast<int>(b.size()), &out, &detail);
    EXPECT_TRUE(p == MessageProblem::kNone || !detail.empty()) << M::getTypeName() << " " << at;
  }
}

TEST(LcmMessages, NoStringLengthReachesTheGeneratedDecoderUnchecked) {
  command_t c{};
  c.path = "12 57";
  everyWindowAtIntMin(c);
  covariance_t cov{};
  cov.error = "unknown pose id";
  everyWindowAtIntMin(cov);
  status_t st{};
  st.num_reasons = 2;
  st.reason = {"nan", "dim"};
  st.reason_count = {1, 2};
  st.batch_winner = "lm";
  st.last_command_result = "disabled 1 edge";
  everyWindowAtIntMin(st);
  // The layout the prechecks walk: batch_winner's and last_command_result's length fields.
  const std::vector<std::uint8_t> b = encodeMessage(st);
  const std::size_t winner = 96 + 4 + (4 + 4) * 2 + 8 * 2 + 128;
  EXPECT_EQ(b[winner + 3], 3);  // "lm" and its NUL
  EXPECT_EQ(std::string(reinterpret_cast<const char*>(&b[winner + 4])), "lm");
  const std::size_t result = winner + 4 + 3 + 154;
  EXPECT_EQ(b[result + 3], st.last_command_result.size() + 1);
  EXPECT_EQ(std::string(reinterpret_cast<const char*>(&b[result + 4])), st.last_command_result);
}

TEST(LcmMessages, AMessageCutShortBeforeALengthFieldIsRefusedWithADetail) {
  command_t c{};
  c.path = "12 57";
  estimate_t e{};
  status_t s{};
  covariance_t cov{};
  const std::vector<std::vector<std::uint8_t>> all = {encodeMessage(c), encodeMessage(e),
                                                      encodeMessage(s), encodeMessage(cov)};
  for (const auto& full : all) {
    for (std::size_t n = 8; n < full.size(); ++n) {
      std::string detail;
      MessageProblem p = MessageProblem::kNone;
      switch (&full - all.data()) {
        case 0: {
          command_t m;
          p = decodeMessage(full.data(), static_cast<int>(n), &m, &detail);
          break;
        }
        case 1: {
          estimate_t m;
          p = decodeMessage(full.data(), static_cast<int>(n), &m, &detail);
          break;
        }
        case 2: {
          status_t m;
          p = decodeMessage(full.data(), static_cast<int>(n), &m, &detail);
          break;
        }
        default: {
          covariance_t m;
          p = decodeMessage(full.data(), static_cast<int>(n), &m, &detail);
          break;
        }
      }
      EXPECT_NE(p, MessageProblem::kNone) << n;
      EXPECT_FALSE(detail.empty()) << "message " << (&full - all.data()) << ", " << n << " bytes";
    }
  }
}

TEST(LcmMessages, EachBadFieldHasItsReason) {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const double inf = std::numeric_limits<double>::infinity();
  const edge_t good2 = makeEdgeMessage(sampleEdge2());
  const edge_t good3 = makeEdgeMessage(sampleEdge3());
  EXPECT_EQ(problemOf(good2), MessageProblem::kNone);
  EXPECT_EQ(problemOf(good3), MessageProblem::kNone);
  auto check = [&](const edge_t& base, auto mutate, MessageProblem expected) {
    edge_t m = base;
    mutate(m);
    EXPECT_EQ(problemOf(m), expected) << toString(expected);
  };
  check(
      good2, [](edge_t& m) { m.dim = 4; }, MessageProblem::kDim);
  check(
      good2, [](edge_t& m) { m.dim = 3; }, MessageProblem::kDim);  // 6 entries for 3D
  check(
      good3, [](edge_t& m) { m.dim = 2; }, MessageProblem::kDim);
  check(
      good2, [](edge_t& m) { m.translation[2] = 1; }, MessageProblem::kDim);
  check(
      good2, [](edge_t& m) { m.rotation[1] = 0.5; }, MessageProblem::kDim);
  check(
      good2, [&](edge_t& m) { m.translation[0] = nan; }, MessageProblem::kNotFinite);
  check(
      good3, [&](edge_t& m) { m.rotation[2] = inf; }, MessageProblem::kNotFinite);
  check(
      good3, [&](edge_t& m) { m.information[4] = nan; }, MessageProblem::kNotFinite);
  check(
      good3,
      [](edge_t& m) {
        m.rotation[0] *= 0.5;
        m.rotation[1] *= 0.5;
        m.rotation[2] *= 0.5;
        m.rotation[3] *= 0.5;
      },
      MessageProblem::kRotation);
  check(
      good2, [](edge_t& m) { m.information[0] = -1; }, MessageProblem::kInformation);
  check(
      good3, [](edge_t& m) { m.information[1] = 1000; }, MessageProblem::kInformation);
  check(
      good2, [](edge_t& m) { m.to_id = m.from_id; }, MessageProblem::kSelfLoop);
  check(
      good2, [](edge_t& m) { m.from_id = -1; }, MessageProblem::kId);
  check(
      good2, [](edge_t& m) { m.seq = 0; }, MessageProblem::kSeq);
  check(
      good2,
      [](edge_t& m) {
        m.information_size = 5;
        m.information.resize(5);
      },
      MessageProblem::kDim);
}

TEST(LcmMessages, RandomCorruptionNeverThrows) {
  const auto good = encodeMessage(makeEdgeMessage(sampleEdge3()));
  std::mt19937 rng(5);
  int accepted = 0;
  for (int trial = 0; trial < 3000; ++trial) {
    auto bytes = good;
    const int flips = 1 + static_cast<int>(rng() % 4);
    for (int f = 0; f < flips; ++f) bytes[rng() % bytes.size()] = static_cast<uint8_t>(rng());
    bytes.resize(bytes.size() - rng() % 3);
    EdgeDecoding d;
    ASSERT_NO_THROW(d = decodeEdge(bytes.data(), static_cast<int>(bytes.size())));
    if (d.ok()) ++accepted;
  }
  EXPECT_LT(accepted, 3000);  // most corruptions are caught (flips of a value may still be valid)
}

StreamPosePrior<SE2> samplePosePrior2() {
  StreamPosePrior<SE2> p;
  p.utime = 77;
  p.sender = 5;
  p.seq = 3;
  p.id = 12;
  p.z = SE2(4.5, -1.25, -2.9);
  p.offset = SE2(0.2, 0.1, 0.05);
  p.omega << 30, 1, 0, 1, 20, 2, 0, 2, 400;
  return p;
}

StreamPosePrior<SE3> samplePosePrior3() {
  StreamPosePrior<SE3> p;
  p.sender = 2;
  p.seq = 1;
  p.id = 0;
  p.z = SE3(Eigen::Quaterniond(0.3, -0.5, 0.1, 0.8).normalized(), Eigen::Vector3d(-7, 8, 0.5));
  p.offset = SE3(Eigen::Quaterniond(0.99, 0.05, 0, 0.1).normalized(), Eigen::Vector3d(0, 0, 1));
  p.omega = Eigen::Matrix<double, 6, 6>::Identity() * 10;
  p.omega(1, 4) = p.omega(4, 1) = 2;
  return p;
}

StreamPositionPrior<SE2> samplePositionPrior2() {
  StreamPositionPrior<SE2> p;
  p.sender = 9;
  p.seq = 8;
  p.id = 40;
  p.p = Eigen::Vector2d(100.5, -20.25);
  p.omega << 4, 0.5, 0.5, 2;
  return p;
}

StreamPositionPrior<SE3> samplePositionPrior3() {
  StreamPositionPrior<SE3> p;
  p.sender = 9;
  p.seq = 9;
  p.id = 41;
  p.p = Eigen::Vector3d(1, 2, -3);
  p.omega << 4, 0.5, 0, 0.5, 2, 0.1, 0, 0.1, 1;
  return p;
}

MessageProblem problemOf(const prior_t& m, std::string* detail = nullptr) {
  const auto bytes = encodeMessage(m);
  const PriorDecoding d = decodePrior(bytes.data(), static_cast<int>(bytes.size()));
  if (detail) *detail = d.detail;
  return d.problem;
}

template <class P>
P decodedAs(const P& prior) {
  const auto bytes = encodeMessage(makePriorMessage(prior));
  const PriorDecoding d = decodePrior(bytes.data(), static_cast<int>(bytes.size()));
  EXPECT_TRUE(d.ok()) << d.detail;
  EXPECT_TRUE(std::holds_alternative<P>(d.prior));
  return std::holds_alternative<P>(d.prior) ? std::get<P>(d.prior) : P();
}

TEST(LcmMessages, PriorRoundTrips) {
  // The offset of information_size that the decoder pre-checks: 158 + 8 n bytes.
  EXPECT_EQ(encodeMessage(makePriorMessage(samplePosePrior2())).size(), 158u + 8u * 6u);
  EXPECT_EQ(encodeMessage(makePriorMessage(samplePosePrior3())).size(), 158u + 8u * 21u);
  EXPECT_EQ(encodeMessage(makePriorMessage(samplePositionPrior2())).size(), 158u + 8u * 3u);
  EXPECT_EQ(encodeMessage(makePriorMessage(samplePositionPrior3())).size(), 158u + 8u * 6u);

  const StreamPosePrior<SE2> a = samplePosePrior2();
  const StreamPosePrior<SE2> a2 = decodedAs(a);
  EXPECT_EQ(a2.utime, 77);
  EXPECT_EQ(a2.sender, 5);
  EXPECT_EQ(a2.seq, 3);
  EXPECT_EQ(a2.id, 12);
  EXPECT_EQ(a2.z.x(), 4.5);
  EXPECT_NEAR(a2.z.angle(), -2.9, 1e-15);
  EXPECT_NEAR(a2.offset.y(), 0.1, 0);
  EXPECT_NEAR(a2.offset.angle(), 0.05, 1e-15);
  EXPECT_EQ(a2.omega, a.omega);
  EXPECT_EQ(dimOf(AnyStreamPrior(a2)), 2);

  const StreamPosePrior<SE3> b = samplePosePrior3();
  const StreamPosePrior<SE3> b2 = decodedAs(b);
  EXPECT_EQ(b2.omega, b.omega);
  EXPECT_LT((b2.z.translation() - b.z.translation()).norm(), 1e-15);
  EXPECT_NEAR(b2.z.quaternion().angularDistance(b.z.quaternion()), 0, 1e-12);
  EXPECT_NEAR(b2.offset.quaternion().angularDistance(b.offset.quaternion()), 0, 1e-12);
  EXPECT_EQ(b2.offset.translation(), b.offset.translation());
  EXPECT_EQ(dimOf(AnyStreamPrior(b2)), 3);

  const StreamPositionPrior<SE2> c = samplePositionPrior2();
  const StreamPositionPrior<SE2> c2 = decodedAs(c);
  EXPECT_EQ(c2.p, c.p);
  EXPECT_EQ(c2.omega, c.omega);
  EXPECT_EQ(c2.id, 40);
  EXPECT_EQ(c2.seq, 8);
  const StreamPositionPrior<SE3> d = samplePositionPrior3();
  const StreamPositionPrior<SE3> d2 = decodedAs(d);
  EXPECT_EQ(d2.p, d.p);
  EXPECT_EQ(d2.omega, d.omega);
  EXPECT_EQ(dimOf(AnyStreamPrior(d2)), 3);

  // An edge is not a prior, nor a prior an edge (the type hash tells them apart).
  const auto edge = encodeMessage(makeEdgeMessage(sampleEdge2()));
  EXPECT_EQ(decodePrior(edge.data(), static_cast<int>(edge.size())).problem,
            MessageProblem::kTypeHash);
  const auto prior = encodeMessage(makePriorMessage(a));
  EXPECT_EQ(decodeEdge(prior.data(), static_cast<int>(prior.size())).problem,
            MessageProblem::kTypeHash);
}

TEST(LcmMessages, EveryPriorTruncationIsRefused) {
  for (const prior_t& m :
       {makePriorMessage(samplePosePrior3()), makePriorMessage(samplePositionPrior2())}) {
    const auto bytes = encodeMessage(m);
    for (size_t n = 0; n < bytes.size(); ++n) {
      const PriorDecoding d = decodePrior(bytes.data(), static_cast<int>(n));
      EXPECT_EQ(d.problem, MessageProblem::kTruncated) << n << " bytes: " << d.detail;
    }
    auto longer = bytes;
    longer.push_back(0);
    EXPECT_EQ(decodePrior(longer.data(), static_cast<int>(longer.size())).problem,
              MessageProblem::kTrailingBytes);
  }
  // information_size (big-endian int32 at byte 154) huge, then negative: refused before the
  // decoder allocates.
  auto bytes = encodeMessage(makePriorMessage(samplePosePrior2()));
  bytes[154] = 0x7f;
  bytes[155] = bytes[156] = bytes[157] = 0xff;
  EXPECT_EQ(decodePrior(bytes.data(), static_cast<int>(bytes.size())).problem,
            MessageProblem::kMalformed);
  bytes[154] = 0xff;
  EXPECT_EQ(decodePrior(bytes.data(), static_cast<int>(bytes.size())).problem,
            MessageProblem::kMalformed);
}

TEST(LcmMessages, EachBadPriorFieldHasItsReason) {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const double inf = std::numeric_limits<double>::infinity();
  const prior_t pose2 = makePriorMessage(samplePosePrior2());
  const prior_t pose3 = makePriorMessage(samplePosePrior3());
  const prior_t pos2 = makePriorMessage(samplePositionPrior2());
  const prior_t pos3 = makePriorMessage(samplePositionPrior3());
  for (const prior_t* m : {&pose2, &pose3, &pos2, &pos3})
    EXPECT_EQ(problemOf(*m), MessageProblem::kNone);
  // Each mutation, its reason and a word its detail must contain.
  auto check = [&](const prior_t& base, auto mutate, MessageProblem expected,
                   const std::string& word) {
    prior_t m = base;
    mutate(m);
    std::string detail;
    EXPECT_EQ(problemOf(m, &detail), expected) << toString(expected) << ": " << detail;
    EXPECT_NE(detail.find(word), std::string::npos) << detail;
  };
  // kind
  check(
      pose2, [](prior_t& m) { m.kind = 0; }, MessageProblem::kKind, "kind 0");
  check(
      pose2, [](prior_t& m) { m.kind = 7; }, MessageProblem::kKind, "kind 7");
  check(
      pos3, [](prior_t& m) { m.rotation[0] = 1; }, MessageProblem::kKind, "position prior");
  check(
      pos2, [](prior_t& m) { m.offset_translation[1] = 0.5; }, MessageProblem::kKind,
      "position prior");
  // A pose prior sent as a position prior: the rotation gives it away (and sizes differ).
  check(
      pose3, [](prior_t& m) { m.kind = prior_t::POSITION; }, MessageProblem::kDim,
      "needs 6 information entries, got 21");
  // dim and sizes
  check(
      pose2, [](prior_t& m) { m.dim = 4; }, MessageProblem::kDim, "dim 4");
  check(
      pose2, [](prior_t& m) { m.dim = 3; }, MessageProblem::kDim, "needs 21");
  check(
      pos3, [](prior_t& m) { m.dim = 2; }, MessageProblem::kDim, "needs 3");
  check(
      pos2,
      [](prior_t& m) {
        m.information_size = 6;
        m.information.resize(6, 0.0);
      },
      MessageProblem::kDim, "position prior needs 3");
  check(
      pos2, [](prior_t& m) { m.translation[2] = 1; }, MessageProblem::kDim, "translation[2]");
  check(
      pose2, [](prior_t& m) { m.rotation[3] = 0.1; }, MessageProblem::kDim, "rotation[1..3]");
  check(
      pose2, [](prior_t& m) { m.offset_translation[2] = 0.1; }, MessageProblem::kDim, "offset");
  // not finite
  check(
      pose2, [&](prior_t& m) { m.translation[1] = nan; }, MessageProblem::kNotFinite,
      "translation");
  check(
      pose3, [&](prior_t& m) { m.rotation[0] = inf; }, MessageProblem::kNotFinite, "rotation");
  check(
      pose3, [&](prior_t& m) { m.offset_rotation[2] = nan; }, MessageProblem::kNotFinite, "offset");
  check(
      pos3, [&](prior_t& m) { m.information[5] = -inf; }, MessageProblem::kNotFinite,
      "information");
  // rotation
  check(
      pose3, [](prior_t& m) { m.rotation[0] = m.rotation[1] = m.rotation[2] = m.rotation[3] = 0; },
      MessageProblem::kRotation, "quaternion norm 0");
  check(
      pose3,
      [](prior_t& m) {
        for (double& q : m.offset_rotation) q = 0;  // the identity offset is 1 0 0 0
      },
      MessageProblem::kRotation, "offset");
  // magnitudes
  check(
      pose2, [](prior_t& m) { m.translation[0] = 1e300; }, MessageProblem::kMagnitude,
      "beyond the largest accepted");
  check(
      pose3, [](prior_t& m) { m.offset_translation[2] = -1e16; }, MessageProblem::kMagnitude,
      "offset");
  check(
      pos3, [](prior_t& m) { m.translation[2] = 2e15; }, MessageProblem::kMagnitude,
      "position prior");
  check(
      pos2, [](prior_t& m) { m.information[0] = 1e31; }, MessageProblem::kInformation,
      "information matrix");
  // information: not positive definite, not symmetric cannot be written (upper triangle)
  check(
      pose2, [](prior_t& m) { m.information[0] = -1; }, MessageProblem::kInformation,
      "information matrix");
  check(
      pos2, [](prior_t& m) { m.information[1] = 10; }, MessageProblem::kInformation,
      "information matrix");  // |Ω01| > √(Ω00 Ω11)
  check(
      pose3, [](prior_t& m) { m.information.assign(21, 0.0); }, MessageProblem::kInformation,
      "information matrix");
  // id, seq
  check(
      pos2, [](prior_t& m) { m.id = -4; }, MessageProblem::kId, "-4");
  check(
      pose2, [](prior_t& m) { m.seq = 0; }, MessageProblem::kSeq, "seq 0");
}

TEST(LcmMessages, EdgeTranslationBeyondTheLimitIsRefused) {
  edge_t m = makeEdgeMessage(sampleEdge3());
  m.translation[1] = 1e200;
  EXPECT_EQ(problemOf(m), MessageProblem::kMagnitude);
  EXPECT_STREQ(toString(MessageProblem::kMagnitude), "magnitude");
  EXPECT_STREQ(toString(MessageProblem::kKind), "kind");
}

TEST(LcmMessages, RandomPriorCorruptionNeverThrows) {
  std::mt19937 rng(6);
  int accepted = 0;
  for (const prior_t& m :
       {makePriorMessage(samplePosePrior3()), makePriorMessage(samplePositionPrior2())}) {
    const auto good = encodeMessage(m);
    for (int trial = 0; trial < 2000; ++trial) {
      auto bytes = good;
      const int flips = 1 + static_cast<int>(rng() % 4);
      for (int f = 0; f < flips; ++f) bytes[rng() % bytes.size()] = static_cast<uint8_t>(rng());
      bytes.resize(bytes.size() - rng() % 3);
      PriorDecoding d;
      ASSERT_NO_THROW(d = decodePrior(bytes.data(), static_cast<int>(bytes.size())));
      if (d.ok()) ++accepted;
    }
  }
  EXPECT_LT(accepted, 4000);
}

StreamEdgeCommand sampleCommand() {
  StreamEdgeCommand c;
  c.utime = 99;
  c.sender = 4;
  c.seq = 17;
  c.kind = StreamEdgeCommand::Kind::kDisable;
  c.from = 130;
  c.to = 105;
  return c;
}

MessageProblem problemOf(const edge_command_t& m, std::string* detail) {
  const auto bytes = encodeMessage(m);
  const EdgeCommandDecoding d = decodeEdgeCommand(bytes.data(), static_cast<int>(bytes.size()));
  *detail = d.detail;
  return d.problem;
}

TEST(LcmMessages, EdgeCommandRoundTrips) {
  for (const auto kind : {StreamEdgeCommand::Kind::kDisable, StreamEdgeCommand::Kind::kEnable}) {
    StreamEdgeCommand c = sampleCommand();
    c.kind = kind;
    const edge_command_t m = makeEdgeCommandMessage(c);
    EXPECT_EQ(m.command, kind == StreamEdgeCommand::Kind::kDisable ? edge_command_t::DISABLE_EDGE
                                                                   : edge_command_t::ENABLE_EDGE);
    const auto bytes = encodeMessage(m);
    EXPECT_EQ(bytes.size(), 8u + 3 * 8 + 1 + 2 * 8);  // hash, utime sender seq, command, ids
    const EdgeCommandDecoding d = decodeEdgeCommand(bytes.data(), static_cast<int>(bytes.size()));
    ASSERT_TRUE(d.ok()) << d.detail;
    EXPECT_EQ(d.command.utime, 99);
    EXPECT_EQ(d.command.sender, 4);
    EXPECT_EQ(d.command.seq, 17);
    EXPECT_EQ(d.command.kind, kind);
    EXPECT_EQ(d.command.from, 130);
    EXPECT_EQ(d.command.to, 105);
  }
  // The largest ids and seq are valid messages (an unknown pose is the smoother's to refuse).
  StreamEdgeCommand big = sampleCommand();
  big.from = big.seq = std::numeric_limits<std::int64_t>::max();
  big.to = 0;
  const auto bytes = encodeMessage(makeEdgeCommandMessage(big));
  EXPECT_TRUE(decodeEdgeCommand(bytes.data(), static_cast<int>(bytes.size())).ok());
}

TEST(LcmMessages, EachBadEdgeCommandFieldHasItsReason) {
  const edge_command_t good = makeEdgeCommandMessage(sampleCommand());
  auto check = [&](auto mutate, MessageProblem expected, const std::string& words) {
    edge_command_t m = good;
    mutate(m);
    std::string detail;
    EXPECT_EQ(problemOf(m, &detail), expected) << toString(expected) << ": " << detail;
    EXPECT_NE(detail.find(words), std::string::npos) << detail;
  };
  check([](edge_command_t& m) { m.command = 0; }, MessageProblem::kKind, "command 0");
  check([](edge_command_t& m) { m.command = 3; }, MessageProblem::kKind, "command 3");
  check([](edge_command_t& m) { m.command = -128; }, MessageProblem::kKind, "command -128");
  check([](edge_command_t& m) { m.from_id = -1; }, MessageProblem::kId, "from_id -1");
  check([](edge_command_t& m) { m.to_id = std::numeric_limits<std::int64_t>::min(); },
        MessageProblem::kId, "to_id -9223372036854775808");
  check([](edge_command_t& m) { m.to_id = m.from_id; }, MessageProblem::kSelfLoop, "both 130");
  check([](edge_command_t& m) { m.seq = 0; }, MessageProblem::kSeq, "seq 0");
  check([](edge_command_t& m) { m.seq = -5; }, MessageProblem::kSeq, "seq -5");
  // Bytes: every truncation, trailing bytes, another type's bytes.
  const auto bytes = encodeMessage(good);
  for (size_t n = 0; n < bytes.size(); ++n) {
    const EdgeCommandDecoding d = decodeEdgeCommand(bytes.data(), static_cast<int>(n));
    EXPECT_EQ(d.problem, MessageProblem::kTruncated) << n << " bytes: " << d.detail;
  }
  auto longer = bytes;
  longer.push_back(0);
  EXPECT_EQ(decodeEdgeCommand(longer.data(), static_cast<int>(longer.size())).problem,
            MessageProblem::kTrailingBytes);
  const auto edge = encodeMessage(makeEdgeMessage(sampleEdge2()));
  const EdgeCommandDecoding d = decodeEdgeCommand(edge.data(), static_cast<int>(edge.size()));
  EXPECT_EQ(d.problem, MessageProblem::kTypeHash);
  EXPECT_NE(d.detail.find("edge_command_t"), std::string::npos) << d.detail;
  command_t service;  // the service's own commands are another type
  service.command = command_t::REFINE;
  const auto other = encodeMessage(service);
  EXPECT_EQ(decodeEdgeCommand(other.data(), static_cast<int>(other.size())).problem,
            MessageProblem::kTypeHash);
  EXPECT_EQ(decodeEdgeCommand(nullptr, 0).problem, MessageProblem::kTruncated);
}

TEST(LcmMessages, RandomEdgeCommandCorruptionNeverThrows) {
  std::mt19937 rng(8);
  const auto good = encodeMessage(makeEdgeCommandMessage(sampleCommand()));
  int accepted = 0;
  for (int trial = 0; trial < 4000; ++trial) {
    auto bytes = good;
    const int flips = 1 + static_cast<int>(rng() % 4);
    for (int f = 0; f < flips; ++f) bytes[rng() % bytes.size()] = static_cast<uint8_t>(rng());
    bytes.resize(bytes.size() - rng() % 3);
    EdgeCommandDecoding d;
    ASSERT_NO_THROW(d = decodeEdgeCommand(bytes.data(), static_cast<int>(bytes.size())));
    if (d.ok()) {
      ++accepted;
      EXPECT_GE(d.command.from, 0);
      EXPECT_GE(d.command.to, 0);
      EXPECT_NE(d.command.from, d.command.to);
      EXPECT_GE(d.command.seq, 1);
    }
  }
  EXPECT_LT(accepted, 4000);
}

TEST(LcmJournal, AppendReadAndTornTail) {
  const std::string path = "/tmp/arbor_lcm_journal_test_" + std::to_string(getpid()) + ".lcmlog";
  std::remove(path.c_str());
  EXPECT_TRUE(readEventLog(path).events.empty());
  {
    EventLogWriter w(path, -1);
    for (int k = 0; k < 5; ++k) {
      const std::string payload(10 + k, static_cast<char>('a' + k));
      w.append("CH" + std::to_string(k), 1000 + k, payload.data(),
               static_cast<int>(payload.size()));
    }
    EXPECT_EQ(w.eventsWritten(), 5);
  }
  EventLogContents c = readEventLog(path);
  ASSERT_EQ(c.events.size(), 5u);
  EXPECT_EQ(c.events[3].channel, "CH3");
  EXPECT_EQ(c.events[3].timestamp, 1003);
  EXPECT_EQ(c.events[3].data.size(), 13u);
  EXPECT_EQ(c.valid_bytes, c.file_bytes);

  // A torn tail (half an event, as after kill -9 during a write) is ignored and cut on reopen.
  {
    std::ofstream out(path, std::ios::binary | std::ios::app);
    const char half[] = {'\xED', '\xA1', '\xDA', '\x01', 0, 0, 0};
    out.write(half, sizeof half);
  }
  c = readEventLog(path);
  ASSERT_EQ(c.events.size(), 5u);
  EXPECT_LT(c.valid_bytes, c.file_bytes);
  {
    EventLogWriter w(path, c.valid_bytes, EventLogWriterOptions{50});
    w.append("AFTER", 7, "xyz", 3);
    w.sync();
  }
  c = readEventLog(path);
  ASSERT_EQ(c.events.size(), 6u);
  EXPECT_EQ(c.events[5].channel, "AFTER");
  EXPECT_EQ(c.valid_bytes, c.file_bytes);
  std::remove(path.c_str());
}

// Damage inside the log (here: event 4's channel-length field overwritten, as a bad sector
// might) must not cost the events after it: they are read, the stretch is reported, and a writer
// opened at valid_bytes keeps them in the file.
TEST(LcmJournal, DamageInsideTheLogSkipsOnlyTheDamagedEvent) {
  const std::string path =
      "/tmp/arbor_lcm_journal_damage_test_" + std::to_string(getpid()) + ".lcmlog";
  std::remove(path.c_str());
  std::vector<std::int64_t> starts;  // file offset of each event
  {
    EventLogWriter w(path, -1);
    std::int64_t offset = 0;
    for (int k = 0; k < 10; ++k) {
      const std::string payload(16 + k, static_cast<char>('a' + k));
      starts.push_back(offset);
      w.append("CH" + std::to_string(k), 2000 + k, payload.data(),
               static_cast<int>(payload.size()));
      offset += 4 + 8 + 8 + 4 + 4 + 3 + static_cast<std::int64_t>(payload.size());  // header
    }
  }
  {
    std::fstream f(path, std::ios::binary | std::ios::in | std::ios::out);
    f.seekp(starts[4] + 20);  // after sync word, event number and timestamp
    const char garbage[4] = {'\x7f', '\x7f', '\x7f', '\x7f'};
    f.write(garbage, sizeof garbage);
  }
  EventLogContents c = readEventLog(path);
  ASSERT_EQ(c.events.size(), 9u);
  EXPECT_EQ(c.events[3].channel, "CH3");
  EXPECT_EQ(c.events[4].channel, "CH5");
  EXPECT_EQ(c.events[8].channel, "CH9");
  ASSERT_EQ(c.damaged.size(), 1u);
  EXPECT_EQ(c.damaged[0].first, starts[4]);
  EXPECT_EQ(c.damaged[0].second, starts[5]);
  EXPECT_EQ(c.valid_bytes, c.file_bytes);
  {
    EventLogWriter w(path, c.valid_bytes);
    w.append("AFTER", 9, "xyz", 3);
    w.sync();
  }
  c = readEventLog(path);
  ASSERT_EQ(c.events.size(), 10u);
  EXPECT_EQ(c.events[8].channel, "CH9");
  EXPECT_EQ(c.events[9].channel, "AFTER");
  // Damage and then a torn tail: the events between are kept, the tail is not "damage".
  {
    std::ofstream out(path, std::ios::binary | std::ios::app);
    const char half[] = {'\xED', '\xA1', '\xDA', '\x01', 0, 0};
    out.write(half, sizeof half);
  }
  c = readEventLog(path);
  EXPECT_EQ(c.events.size(), 10u);
  EXPECT_EQ(c.damaged.size(), 1u);
  EXPECT_EQ(c.file_bytes - c.valid_bytes, 6);
  std::remove(path.c_str());
}

// One byte corrupted anywhere in a 50-event log (500 positions and values from a fixed seed)
// costs at most a few events: those it falls in and, when it changes a length, the next one or
// two; never the rest of the log. (The reader used to stop at the first bad header.)
TEST(LcmJournal, ASingleCorruptedByteCostsAFewEventsAtMost) {
  const std::string path =
      "/tmp/arbor_lcm_journal_byte_test_" + std::to_string(getpid()) + ".lcmlog";
  const std::string copy = path + ".corrupt";
  std::remove(path.c_str());
  {
    EventLogWriter w(path, -1);
    for (int k = 0; k < 50; ++k) {
      const std::string payload(20 + k % 7, static_cast<char>('a' + k % 26));
      w.append("CH" + std::to_string(k), 1000 + k, payload.data(),
               static_cast<int>(payload.size()));
    }
  }
  std::vector<char> bytes;
  {
    std::ifstream in(path, std::ios::binary);
    bytes.assign(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
  }
  std::mt19937 rng(11);
  size_t fewest = 50, total = 0;
  for (int trial = 0; trial < 500; ++trial) {
    std::vector<char> b = bytes;
    b[rng() % b.size()] = static_cast<char>(rng());
    {
      std::ofstream out(copy, std::ios::binary | std::ios::trunc);
      out.write(b.data(), static_cast<std::streamsize>(b.size()));
    }
    const EventLogContents c = readEventLog(copy);
    fewest = std::min(fewest, c.events.size());
    total += c.events.size();
  }
  EXPECT_GE(fewest, 46u);
  EXPECT_GE(static_cast<double>(total) / 500, 49.0);
  std::remove(path.c_str());
  std::remove(copy.c_str());
}

}  // namespace
}  // namespace arbor
