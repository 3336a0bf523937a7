// Writes the seed corpus of every fuzz target (tests/fuzz/corpus/<target>/, checked in):
// valid inputs of each kind, from which the fuzzers' mutations start. Regenerate with
//   build/tests/fuzz/arbor-fuzz-corpus tests/fuzz/corpus
// (files of the same name are overwritten; regression inputs added by hand are kept).
// Deterministic: the same files on every run.
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <sstream>
#include <string>
#include <vector>

#include "arbor_slam/io/lcm_journal.h"
#include "arbor_slam/io/lcm_messages.h"
#include "arbor_slam/io/pose_graph_file.h"
#include "arbor_slam/tests/lcm_datagrams.h"
#include "arbor_slam/tools/serve/bus_auth.h"

namespace fs = std::filesystem;
using namespace arbor;
using Bytes = std::vector<std::uint8_t>;

namespace {

fs::path g_root;

void put(const std::string& target, const std::string& name, const Bytes& bytes) {
  const fs::path dir = g_root / target;
  fs::create_directories(dir);
  std::ofstream out(dir / name, std::ios::binary);
  out.write(reinterpret_cast<const char*>(bytes.data()),
            static_cast<std::streamsize>(bytes.size()));
}

void putText(const std::string& target, const std::string& name, const std::string& text) {
  put(target, name, Bytes(text.begin(), text.end()));
}

StreamEdge<SE2> edge2(std::int64_t seq, Key from, Key to) {
  StreamEdge<SE2> e;
  e.utime = 1000 + seq;
  e.sender = 1;
  e.seq = seq;
  e.from = from;
  e.to = to;
  e.z = SE2(1.0, 0.1, 0.05);
  e.omega.diagonal() << 100, 100, 400;
  return e;
}

StreamEdge<SE3> edge3(std::int64_t seq, Key from, Key to) {
  StreamEdge<SE3> e;
  e.utime = 2000 + seq;
  e.sender = 2;
  e.seq = seq;
  e.from = from;
  e.to = to;
  SE3::Tangent tau;
  tau << 1.0, 0.2, -0.1, 0.01, 0.02, 0.3;
  e.z = SE3::Exp(tau);
  e.omega.diagonal() << 100, 100, 100, 400, 400, 400;
  e.omega(0, 1) = e.omega(1, 0) = 5;
  return e;
}

std::vector<Bytes> edges() {
  StreamEdge<SE2> trusted = edge2(3, 4, 9);
  trusted.trust = EdgeTrust::kTrusted;
  trusted.kernel = KernelKind::kCauchy;
  StreamEdge<SE3> robust = edge3(4, 0, 7);
  robust.trust = EdgeTrust::kRobust;
  robust.kernel = KernelKind::kTruncatedLeastSquares;
  return {encodeMessage(makeEdgeMessage(edge2(1, 0, 1))),
          encodeMessage(makeEdgeMessage(edge3(2, 1, 2))),
          encodeMessage(makeEdgeMessage(trusted)),
          encodeMessage(makeEdgeMessage(robust)),
          encodeMessage(makeEdgeV1Message(edge2(5, 1, 2))),
          encodeMessage(makeEdgeV1Message(edge3(6, 2, 3)))};
}

std::vector<Bytes> priors() {
  StreamPosePrior<SE2> p2;
  p2.sender = 1;
  p2.seq = 1;
  p2.id = 0;
  p2.z = SE2(0.5, -0.5, 0.2);
  StreamPosePrior<SE3> p3;
  p3.sender = 2;
  p3.seq = 2;
  p3.id = 4;
  SE3::Tangent tau;
  tau << 0.1, 0.2, 0.3, 0.0, 0.1, 0.0;
  p3.z = SE3::Exp(tau);
  p3.offset = SE3::Exp(0.5 * tau);
  StreamPositionPrior<SE2> q2;
  q2.sender = 3;
  q2.seq = 1;
  q2.id = 7;
  q2.p << 3.0, 4.0;
  StreamPositionPrior<SE3> q3;
  q3.sender = 3;
  q3.seq = 2;
  q3.id = 8;
  q3.p << 1.0, 2.0, 3.0;
  q3.omega(0, 2) = q3.omega(2, 0) = 0.5;
  return {encodeMessage(makePriorMessage(p2)), encodeMessage(makePriorMessage(p3)),
          encodeMessage(makePriorMessage(q2)), encodeMessage(makePriorMessage(q3))};
}

std::vector<Bytes> edgeCommands() {
  StreamEdgeCommand c;
  c.sender = 1;
  c.seq = 1;
  c.from = 3;
  c.to = 9;
  StreamEdgeCommand d = c;
  d.seq = 2;
  d.kind = StreamEdgeCommand::Kind::kEnable;
  return {encodeMessage(makeEdgeCommandMessage(c)), encodeMessage(makeEdgeCommandMessage(d))};
}

std::vector<Bytes> commands() {
  std::vector<Bytes> out;
  const std::pair<int, const char*> kinds[] = {
      {command_t::REFINE, ""},          {command_t::PUBLISH_FULL, ""},
      {command_t::SNAPSHOT, "out.g2o"}, {command_t::STATUS, ""},
      {command_t::BATCH, ""},           {command_t::COVARIANCE, "12 57"},
      {command_t::COVARIANCE, "3"},     {command_t::CLOSURES, "closures.txt"}};
  for (const auto& [kind, path] : kinds) {
    command_t c;
    c.utime = 77;
    c.command = static_cast<std::int8_t>(kind);
    c.path = path;
    out.push_back(encodeMessage(c));
  }
  return out;
}

std::vector<Bytes> estimates() {
  estimate_t e2{};
  e2.utime = 5;
  e2.update = 3;
  e2.full = true;
  e2.dim = 2;
  e2.total_poses = 3;
  e2.F = 1.5;
  e2.num_poses = 3;
  for (int k = 0; k < 3; ++k) {
    e2.ids.push_back(k);
    e2.translation.push_back({1.0 * k, 0.5 * k, 0.0});
    e2.rotation.push_back({0.1 * k, 0.0, 0.0, 0.0});
  }
  estimate_t e3 = e2;
  e3.dim = 3;
  e3.full = false;
  e3.total_poses = 10;
  e3.num_poses = 2;
  e3.ids = {4, 9};
  e3.translation = {{1, 2, 3}, {4, 5, 6}};
  e3.rotation = {{1, 0, 0, 0}, {0.5, 0.5, 0.5, 0.5}};
  return {encodeMessage(e2), encodeMessage(e3)};
}

std::vector<Bytes> statuses() {
  status_t s{};
  s.utime = 9;
  s.received = 10;
  s.accepted = 8;
  s.applied = 8;
  s.rejected = 2;
  s.num_reasons = 2;
  s.reason = {"truncated", "nan"};
  s.reason_count = {1, 1};
  s.F = 3.25;
  status_t empty{};
  return {encodeMessage(s), encodeMessage(empty)};
}

std::vector<Bytes> covariances() {
  covariance_t c{};
  c.utime = 1;
  c.request = 77;
  c.num_ids = 2;
  c.ids = {12, 57};
  c.update = 4;
  c.dim = 6;
  c.matrix.assign(6, std::vector<double>(6, 0.0));
  for (int k = 0; k < 6; ++k) c.matrix[k][k] = 0.01 * (k + 1);
  covariance_t refused{};
  refused.request = 78;
  refused.error = "unknown pose id 99";
  return {encodeMessage(c), encodeMessage(refused)};
}

std::vector<Bytes> marks() {
  journal_mark_t u{};
  u.utime = 3;
  u.kind = journal_mark_t::UPDATE;
  u.edges = 5;
  u.update = 1;
  journal_mark_t r = u;
  r.kind = journal_mark_t::REFINE;
  r.edges = 0;
  r.update = 2;
  return {encodeMessage(u), encodeMessage(r)};
}

std::vector<Bytes> resends() {
  ResendMessage request;
  request.utime = 9;
  request.sender = 1;
  request.settled = 10;
  request.highest = 40;
  request.missing = {{11, 12}, {20, 20}, {30, 39}};
  ResendMessage window;
  window.request = false;
  window.priors = true;
  window.sender = 2;
  window.settled = 100;
  window.highest = 500;
  return {encodeMessage(makeResendMessage(request)), encodeMessage(makeResendMessage(window))};
}

void putAll(const std::string& target, const std::string& stem, const std::vector<Bytes>& all) {
  for (std::size_t k = 0; k < all.size(); ++k) put(target, stem + std::to_string(k), all[k]);
}

Bytes fileBytes(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  return Bytes(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
}

void be(Bytes& d, std::uint64_t v, int bytes) {
  for (int k = bytes - 1; k >= 0; --k) d.push_back(static_cast<std::uint8_t>(v >> (8 * k)));
}

// An event as lcm-logger writes it (event number n, no checksum: a log from before them).
void uncheckedEvent(Bytes& log, std::uint64_t n, const std::string& channel, const Bytes& data,
                    std::uint32_t data_length) {
  be(log, 0xEDA1DA01, 4);
  be(log, n, 8);
  be(log, 1000 + n, 8);
  be(log, channel.size(), 4);
  be(log, data_length, 4);
  log.insert(log.end(), channel.begin(), channel.end());
  log.insert(log.end(), data.begin(), data.end());
}

void journals(const fs::path& scratch) {
  const std::vector<Bytes> e = edges(), p = priors(), c = edgeCommands(), m = marks(),
                           est = estimates();
  const fs::path path = scratch / "journal.lcmlog";
  fs::remove(path);
  {
    EventLogWriter w(path.string(), -1);
    w.append("ARBOR_EDGES", 1, e[0].data(), static_cast<int>(e[0].size()));
    w.append("ARBOR_EDGES", 2, e[1].data(), static_cast<int>(e[1].size()));
    w.append("ARBOR_PRIORS", 3, p[0].data(), static_cast<int>(p[0].size()));
    w.append("ARBOR_EDGE_COMMANDS", 4, c[0].data(), static_cast<int>(c[0].size()));
    w.append("ARBOR_JOURNAL_MARK", 5, m[0].data(), static_cast<int>(m[0].size()),
             EventClass::kRecord);
    w.append("ARBOR_JOURNAL_RESEED", 6, est[0].data(), static_cast<int>(est[0].size()),
             EventClass::kRecord);
    w.append("ARBOR_JOURNAL_MARK", 7, m[1].data(), static_cast<int>(m[1].size()),
             EventClass::kRecord);
  }
  const Bytes checked = fileBytes(path);
  put("journal_reader", "checked", checked);
  // Torn: the last event cut short (kill -9 mid-write).
  put("journal_reader", "torn_tail", Bytes(checked.begin(), checked.end() - 9));
  // Junk after the last event (a torn write of another size).
  Bytes junk = checked;
  for (int k = 0; k < 40; ++k) junk.push_back(static_cast<std::uint8_t>(37 * k));
  put("journal_reader", "junk_tail", junk);
  // Unchecked (before checksums), then checked events after it.
  Bytes old;
  uncheckedEvent(old, 0, "ARBOR_EDGES", e[2], static_cast<std::uint32_t>(e[2].size()));
  uncheckedEvent(old, 1, "ARBOR_PRIORS", p[3], static_cast<std::uint32_t>(p[3].size()));
  uncheckedEvent(old, 2, "ARBOR_JOURNAL_MARK", m[0], static_cast<std::uint32_t>(m[0].size()));
  put("journal_reader", "unchecked", old);
  Bytes mixed = old;
  mixed.insert(mixed.end(), checked.begin(), checked.end());
  put("journal_reader", "unchecked_then_checked", mixed);
  // Issue 56: an event whose data length reads 0x7FFFFFFF, between sound ones.
  Bytes huge;
  uncheckedEvent(huge, 0, "ARBOR_EDGES", e[0], 0x7FFFFFFF);
  huge.insert(huge.end(), checked.begin(), checked.end());
  put("journal_reader", "length_7fffffff", huge);
  fs::remove(path);
}

// A datagram stream as udpm_datagram_fuzz.cc reads it: [source][length, 2 bytes][datagram].
void frame(Bytes& stream, std::uint8_t source, const Bytes& d) {
  stream.push_back(source);
  be(stream, d.size(), 2);
  stream.insert(stream.end(), d.begin(), d.end());
}

void datagrams() {
  using testing::lcmDatagrams;
  const std::vector<Bytes> e = edges(), est = estimates(), c = commands();
  Bytes whole;
  frame(whole, 0, lcmDatagrams("ARBOR_EDGES", e[0], 1)[0]);
  frame(whole, 1, lcmDatagrams("ARBOR_EDGES", e[1], 1)[0]);
  frame(whole, 0, lcmDatagrams("ARBOR_COMMAND", c[5], 2)[0]);
  frame(whole, 2, lcmDatagrams("SKIPPED", e[0], 1)[0]);
  put("udpm_datagram", "whole", whole);
  // An estimate in fragments of 64 bytes: in order; the later ones reversed; two sources
  // interleaved.
  const auto fragments = lcmDatagrams("ARBOR_ESTIMATE", est[1], 9, 64, 52);
  Bytes in_order, reversed, interleaved;
  for (const auto& f : fragments) frame(in_order, 1, f);
  frame(reversed, 1, fragments[0]);
  for (std::size_t k = fragments.size(); k-- > 1;) frame(reversed, 1, fragments[k]);
  const auto other = lcmDatagrams("ARBOR_EDGES", e[3], 4, 64, 52);
  for (std::size_t k = 0; k < std::max(fragments.size(), other.size()); ++k) {
    if (k < fragments.size()) frame(interleaved, 1, fragments[k]);
    if (k < other.size()) frame(interleaved, 2, other[k]);
  }
  put("udpm_datagram", "fragments_in_order", in_order);
  put("udpm_datagram", "fragments_reversed", reversed);
  put("udpm_datagram", "fragments_interleaved", interleaved);
  // Issue 56's 544-byte datagram, then a valid message from the same source.
  Bytes wrap;
  frame(wrap, 0, testing::wrappingFragment("ARBOR_EDGES"));
  frame(wrap, 0, lcmDatagrams("ARBOR_EDGES", e[0], 8)[0]);
  put("udpm_datagram", "issue56_wrapping_fragment", wrap);
}

void envelopes() {
  std::array<std::uint8_t, 32> secret{};  // the key of bus_envelope_fuzz.cc
  for (std::size_t k = 0; k < secret.size(); ++k) secret[k] = static_cast<std::uint8_t>(7 * k + 1);
  serve::BusAuthOptions options;
  options.sender = 3;
  options.epoch = 1;
  serve::BusAuth auth({serve::busKeyFromSecret(secret)}, options);
  constexpr std::int64_t kNow = 1'700'000'000'000'000;  // bus_envelope_fuzz.cc's clock
  const std::vector<Bytes> e = edges();
  for (std::size_t k = 0; k < 3; ++k) {
    put("bus_envelope", "sealed_edge" + std::to_string(k),
        auth.seal("ARBOR_EDGES", e[k].data(), e[k].size(), kNow));
  }
  put("bus_envelope", "unsigned_edge", e[0]);
}

// Small graphs: the first poses of the data files and the edges among them, TORO, priors.
void graphs(const fs::path& source) {
  for (const char* name : {"manhattan_2d.g2o", "sphere_3d.g2o", "grid_3d.g2o"}) {
    std::ifstream in(source / "data" / name);
    std::string text;
    for (std::string line; std::getline(in, line);) {
      std::istringstream fields(line);
      std::string tag;
      long a = 0, b = 0;
      fields >> tag >> a;
      const bool vertex = tag.rfind("VERTEX", 0) == 0;
      if (!vertex) fields >> b;
      if (a < 8 && (vertex || b < 8)) text += line + "\n";
    }
    putText("g2o_reader", std::string(name) + ".head", text);
  }
  putText("g2o_reader", "toro",
          "VERTEX2 0 0 0 0\nVERTEX2 1 1 0 0.1\nVERTEX2 2 2 0.1 0.2\n"
          "EDGE2 0 1 1 0 0.1 100 0 0 100 0 400\nEDGE2 1 2 1 0.1 0.1 100 0 0 100 0 400\n"
          "EDGE2 0 2 2 0.1 0.2 50 0 0 50 0 200\n");
  putText("g2o_reader", "priors_2d",
          "VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 1 0 0\nFIX 0\n"
          "EDGE_SE2 0 1 1 0 0 100 0 0 100 0 400\n"
          "EDGE_PRIOR_SE2 1 1 0 0 10 0 0 10 0 10\n"
          "EDGE_PRIOR_SE2_XY 1 1 0.1 4 0 4\n"
          "POSITION_PRIOR2 0 0 0 9 0 9\n");
  putText("g2o_reader", "priors_3d",
          "PARAMS_SE3OFFSET 0 0 0 0 0 0 0 1\nPARAMS_SE3OFFSET 1 0.1 0 0 0 0 0 1\n"
          "VERTEX_SE3:QUAT 0 0 0 0 0 0 0 1\nVERTEX_SE3:QUAT 1 1 0 0 0 0 0 1\n"
          "EDGE_SE3:QUAT 0 1 1 0 0 0 0 0 1 100 0 0 0 0 0 100 0 0 0 0 100 0 0 0 400 0 0 400 0 400\n"
          "EDGE_SE3_PRIOR 1 1 1 0 0 0 0 0 1 10 0 0 0 0 0 10 0 0 0 0 10 0 0 0 10 0 0 10 0 10\n"
          "EDGE_SE3_XYZ_PRIOR 0 1 0 0 0 4 0 0 4 0 4\n"
          "POSITION_PRIOR3 1 1 0 0 4 0 0 4 0 4\n");
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 2) {
    std::cerr << "usage: arbor-fuzz-corpus DIR (tests/fuzz/corpus)\n";
    return 2;
  }
  g_root = argv[1];
  const fs::path source = fs::path(ARBOR_SOURCE_DIR);
  putAll("lcm_edge", "edge", edges());
  putAll("lcm_prior", "prior", priors());
  putAll("lcm_edge_command", "edge_command", edgeCommands());
  putAll("lcm_command", "command", commands());
  putAll("lcm_estimate", "estimate", estimates());
  putAll("lcm_status", "status", statuses());
  putAll("lcm_covariance", "covariance", covariances());
  putAll("lcm_journal_mark", "mark", marks());
  putAll("lcm_resend", "resend", resends());
  journals(fs::temp_directory_path());
  datagrams();
  envelopes();
  graphs(source);
  std::cout << "fuzz corpus written under " << g_root << "\n";
  return 0;
}
