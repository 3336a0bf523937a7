// What `arbor publish` sends for a file: its edges and priors in streamOrder
// (tools/cli/replay_order.h), as the messages of one sender. Edges are numbered seq = position
// among the edges from 1, priors seq = position among the priors from 1 (two sequences, as the
// service counts them: docs/lcm.md). --skip K / --count N select edges; a prior goes with the
// edge it follows (the priors on poses no edge touches follow the last edge), so `--count K`
// then `--skip K` send every message once.
#pragma once

#include <algorithm>
#include <cstdint>
#include <stdexcept>
#include <string>
#include <variant>
#include <vector>

#include "arbor_slam/io/lcm_messages.h"
#include "arbor_slam/tools/cli/replay_order.h"

namespace arbor::cli {

/// One message to send: an edge (`is_prior` false) or a prior, utime 0 (set when sent).
template <class G>
struct StreamMessage {
  bool is_prior = false;
  StreamEdge<G> edge;
  AnyStreamPrior prior;
};

struct StreamSelection {
  long edges = 0;                          ///< edges selected
  long priors = 0;                         ///< priors selected
  std::int64_t first_seq = 1;              ///< of the edges selected
  std::int64_t last_seq = 0;               ///< of the edges selected (first_seq − 1 when none)
  long total_edges = 0, total_priors = 0;  ///< in the file
};

/// The messages of `graph` for edges skip .. skip + count − 1 (count < 0: to the end), in
/// stream order. Throws std::invalid_argument if skip exceeds the edges.
template <class G>
std::vector<StreamMessage<G>> streamMessages(const PoseGraph<G>& graph, std::int64_t sender,
                                             long skip, long count, StreamSelection* selection) {
  const std::vector<StreamStep> order = streamOrder(graph);
  const long total = static_cast<long>(graph.edges.size());
  if (skip < 0 || skip > total) {
    throw std::invalid_argument("skip " + std::to_string(skip) + " exceeds the " +
                                std::to_string(total) + " edges");
  }
  const long end = count < 0 ? total : std::min(total, skip + count);
  StreamSelection sel;
  sel.total_edges = total;
  sel.total_priors = static_cast<long>(order.size()) - total;
  sel.first_seq = skip + 1;
  sel.last_seq = end;
  std::vector<StreamMessage<G>> out;
  std::int64_t edge_seq = 0, prior_seq = 0;
  for (const StreamStep& step : order) {
    StreamMessage<G> m;
    if (step.kind == StreamStep::Kind::kEdge) {
      ++edge_seq;
      if (edge_seq <= skip || edge_seq > end) continue;
      const auto& e = graph.edges[step.index];
      m.edge.sender = sender;
      m.edge.seq = edge_seq;
      m.edge.from = graph.ids[e.i];
      m.edge.to = graph.ids[e.j];
      m.edge.z = e.measurement;
      m.edge.omega = e.information;
      ++sel.edges;
      out.push_back(m);
      continue;
    }
    ++prior_seq;
    // With the edge it follows (seq edge_seq; the priors that no edge introduces follow the
    // last edge); in a file without edges, unless count is 0.
    const bool selected = edge_seq == 0 ? count != 0 : edge_seq > skip && edge_seq <= end;
    if (!selected) continue;
    m.is_prior = true;
    if (step.kind == StreamStep::Kind::kPosePrior) {
      const auto& f = graph.pose_priors[step.index];
      StreamPosePrior<G> p;
      p.sender = sender;
      p.seq = prior_seq;
      p.id = graph.ids[f.i];
      p.z = f.measurement;
      p.offset = f.offset;
      p.omega = f.information;
      m.prior = p;
    } else {
      const auto& f = graph.position_priors[step.index];
      StreamPositionPrior<G> p;
      p.sender = sender;
      p.seq = prior_seq;
      p.id = graph.ids[f.i];
      p.p = f.position;
      p.omega = f.information;
      m.prior = p;
    }
    ++sel.priors;
    out.push_back(m);
  }
  if (selection) *selection = sel;
  return out;
}

/// The encoded bytes of a message with `utime`.
template <class G>
std::vector<std::uint8_t> encodeStreamMessage(StreamMessage<G> m, std::int64_t utime) {
  if (!m.is_prior) {
    m.edge.utime = utime;
    return encodeMessage(makeEdgeMessage(m.edge));
  }
  return std::visit(
      [&](auto p) {
        p.utime = utime;
        return encodeMessage(makePriorMessage(p));
      },
      m.prior);
}

}  // namespace arbor::cli
