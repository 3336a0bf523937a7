// Shared by the in-process `arbor serve` tests over memq://: the edges of a generated graph in
// replay order as edge_t bytes, a generated graph with priors and its stream (edges and priors
// as `arbor publish` sends them), and a Collector of the estimates and status on the bus.
#pragma once

#include <algorithm>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <functional>
#include <mutex>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <unistd.h>

#include <lcm/lcm-cpp.hpp>

#include "process_temp_dir.h"

#include "arbor_slam/bayestree/online_smoother.h"
#include "arbor_slam/io/lcm_messages.h"
#include "arbor_slam/tools/cli/publish_stream.h"
#include "arbor_slam/tools/cli/replay_order.h"
#include "arbor_slam/tools/generator/graph_generator.h"
#include "arbor_slam/tools/serve/serve_service.h"

namespace arbor::serve::testing {

/// A generated Manhattan world (grid 4 or 6 in the tests) with the given rotation noise.
inline PoseGraph2 manhattanGraph(int poses, int grid, double sigma_rotation, std::uint64_t seed) {
  sim::ManhattanOptions o;
  o.poses = poses;
  o.grid = grid;
  if (sigma_rotation >= 0) o.noise = {0.05, sigma_rotation};
  o.seed = seed;
  return sim::manhattanWorld(o).graph;
}

/// The graph's edges in the order `arbor replay --step edge` feeds them.
inline std::vector<int> replayOrder(const PoseGraph2& graph) {
  std::vector<int> order;
  for (const auto& g : cli::replayGroups(graph, false))
    order.insert(order.end(), g.begin(), g.end());
  return order;
}

/// The graph's edges fed to an OnlineSmoother in `order`, one update per edge, then finalize():
/// what `arbor replay` computes, without LCM in between.
inline OnlineSmoother2 finalizedReplay(const PoseGraph2& graph, const std::vector<int>& order) {
  OnlineSmoother2 replay;
  for (int e : order) {
    const auto& edge = graph.edges[e];
    replay.addEdge(graph.ids[edge.i], graph.ids[edge.j], edge.measurement, edge.information);
    replay.update();
  }
  replay.finalize();
  return replay;
}

inline StreamEdge<SE2> streamEdge(const PoseGraph2& graph, int e, std::int64_t seq,
                                  std::int64_t sender = 1) {
  StreamEdge<SE2> s;
  s.sender = sender;
  s.seq = seq;
  s.from = graph.ids[graph.edges[e].i];
  s.to = graph.ids[graph.edges[e].j];
  s.z = graph.edges[e].measurement;
  s.omega = graph.edges[e].information;
  return s;
}

inline std::vector<std::uint8_t> edgeBytes(const StreamEdge<SE2>& e) {
  return encodeMessage(makeEdgeMessage(e));
}

inline std::vector<std::uint8_t> edgeBytes(const PoseGraph2& graph, int e, std::int64_t seq) {
  return edgeBytes(streamEdge(graph, e, seq));
}

/// A generated Manhattan world (grid 4, default noise) with priors in a world frame W (not the
/// first pose's): a pose prior with a sensor offset on pose 0 and a position prior (GPS) on
/// every 10th pose from pose 5, each from the ground truth (moved into W).
inline PoseGraph2 manhattanGraphWithPriors(int poses, std::uint64_t seed, SE2* world = nullptr) {
  sim::ManhattanOptions o;
  o.poses = poses;
  o.grid = 4;
  o.seed = seed;
  const sim::Simulation<SE2> sim = sim::manhattanWorld(o);
  PoseGraph2 graph = sim.graph;
  const SE2 w(5.0, -3.0, 0.4);
  const SE2 offset(0.1, -0.05, 0.02);
  const Eigen::Vector3d pose_sigma(0.05, 0.05, 0.02);
  graph.pose_priors.push_back(PosePriorFactor<SE2>::make(
      0, w.compose(sim.truth[0]).compose(offset),
      pose_sigma.cwiseInverse().cwiseAbs2().asDiagonal().toDenseMatrix(), offset));
  for (int k = 5; k < graph.numPoses(); k += 10) {
    graph.position_priors.push_back(PositionPriorFactor<SE2>::make(
        k, w.compose(sim.truth[k]).translation(), 25.0 * Eigen::Matrix2d::Identity()));
  }
  if (world) *world = w;
  return graph;
}

/// The messages `arbor publish` sends for `graph` (every edge and prior, sender 1), encoded.
struct StreamBytes {
  bool is_prior = false;
  std::vector<std::uint8_t> bytes;
};
inline std::vector<StreamBytes> streamBytes(const PoseGraph2& graph,
                                            cli::StreamSelection* selection = nullptr) {
  std::vector<StreamBytes> out;
  for (const auto& m : cli::streamMessages(graph, 1, 0, -1, selection))
    out.push_back({m.is_prior, cli::encodeStreamMessage(m, 0)});
  return out;
}

/// Feeds one message's bytes (as decoded on the wire) to `smoother`; false if it is refused.
inline bool feed(OnlineSmoother2& smoother, const StreamBytes& m) {
  const int size = static_cast<int>(m.bytes.size());
  if (!m.is_prior) {
    const EdgeDecoding d = decodeEdge(m.bytes.data(), size);
    if (!d.ok()) return false;
    const auto& e = std::get<StreamEdge<SE2>>(d.edge);
    return smoother.addEdge(e.from, e.to, e.z, e.omega).status == EdgeStatus::kAccepted;
  }
  const PriorDecoding d = decodePrior(m.bytes.data(), size);
  if (!d.ok()) return false;
  if (const auto* p = std::get_if<StreamPosePrior<SE2>>(&d.prior))
    return smoother.addPosePrior(p->id, p->z, p->omega, p->offset).status == EdgeStatus::kAccepted;
  const auto& p = std::get<StreamPositionPrior<SE2>>(d.prior);
  return smoother.addPositionPrior(p.id, p.p, p.omega).status == EdgeStatus::kAccepted;
}

/// A path in the temp directory unique to this process, removed if it exists.
inline std::string tempPath(const std::string& prefix, const std::string& name) {
  const std::string path = (arbor::testing::processTempDir() / (prefix + "_" + name)).string();
  std::remove(path.c_str());
  return path;
}

/// Receives estimates and status on the bus (dispatched by the service's receive thread when
/// both share one memq:// instance): the last seq covered, the count, the full estimates, the
/// last status.
class Collector {
 public:
  Collector(lcm::LCM& lcm, const Channels& ch) : lcm_(lcm) {
    subs_.push_back(lcm.subscribe(ch.estimate, &Collector::onEstimate, this));
    subs_.push_back(lcm.subscribe(ch.status, &Collector::onStatus, this));
    for (auto* s : subs_) s->setQueueCapacity(0);
  }
  ~Collector() {
    for (auto* s : subs_) lcm_.unsubscribe(s);
  }
  Collector(const Collector&) = delete;
  Collector& operator=(const Collector&) = delete;

  bool waitCovered(std::int64_t seq, double timeout_s = 20) {
    std::unique_lock<std::mutex> lock(mutex_);
    return cv_.wait_for(lock, std::chrono::duration<double>(timeout_s),
                        [&] { return last_seq_ >= seq; });
  }
  bool waitStatus(const std::function<bool(const status_t&)>& pred, double timeout_s = 20) {
    std::unique_lock<std::mutex> lock(mutex_);
    return cv_.wait_for(lock, std::chrono::duration<double>(timeout_s),
                        [&] { return have_status_ && pred(status_); });
  }
  bool waitFull(size_t count, double timeout_s = 20) {
    std::unique_lock<std::mutex> lock(mutex_);
    return cv_.wait_for(lock, std::chrono::duration<double>(timeout_s),
                        [&] { return full_.size() >= count; });
  }
  std::vector<estimate_t> fullEstimates() {
    std::lock_guard<std::mutex> lock(mutex_);
    return full_;
  }
  int estimates() {
    std::lock_guard<std::mutex> lock(mutex_);
    return count_;
  }
  status_t status() {
    std::lock_guard<std::mutex> lock(mutex_);
    return status_;
  }

 private:
  void onEstimate(const lcm::ReceiveBuffer* rbuf, const std::string&) {
    estimate_t m;
    ASSERT_EQ(decodeMessage(rbuf->data, static_cast<int>(rbuf->data_size), &m),
              MessageProblem::kNone);
    std::lock_guard<std::mutex> lock(mutex_);
    ++count_;
    last_seq_ = std::max(last_seq_, m.last_seq);
    if (m.full) full_.push_back(m);
    cv_.notify_all();
  }
  void onStatus(const lcm::ReceiveBuffer* rbuf, const std::string&) {
    status_t s;
    ASSERT_EQ(decodeMessage(rbuf->data, static_cast<int>(rbuf->data_size), &s),
              MessageProblem::kNone);
    std::lock_guard<std::mutex> lock(mutex_);
    status_ = s;
    have_status_ = true;
    cv_.notify_all();
  }
  lcm::LCM& lcm_;
  std::vector<lcm::Subscription*> subs_;
  std::mutex mutex_;
  std::condition_variable cv_;
  std::int64_t last_seq_ = 0;
  int count_ = 0;
  std::vector<estimate_t> full_;
  status_t status_;
  bool have_status_ = false;
};

}  // namespace arbor::serve::testing
