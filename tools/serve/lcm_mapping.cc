#include "arbor_slam/tools/serve/lcm_mapping.h"

#include <algorithm>
#include <string>

#include "arbor_slam/tools/serve/edge_intake.h"

namespace arbor::serve {

Arrival arrivalFromBytes(MeasurementKind kind, const void* data, int size) {
  Arrival a;
  a.kind = kind;
  a.wire = data;
  a.wire_size = size;
  switch (kind) {
    case MeasurementKind::kEdge: {
      EdgeDecoding d = decodeEdge(data, size);
      if (!d.ok()) {
        a.problem = toString(d.problem);
        a.detail = d.detail;
      }
      a.edge = std::move(d.edge);
      break;
    }
    case MeasurementKind::kPrior: {
      PriorDecoding d = decodePrior(data, size);
      if (!d.ok()) {
        a.problem = toString(d.problem);
        a.detail = d.detail;
      }
      a.prior = std::move(d.prior);
      break;
    }
    case MeasurementKind::kCommand: {
      EdgeCommandDecoding d = decodeEdgeCommand(data, size);
      if (!d.ok()) {
        a.problem = toString(d.problem);
        a.detail = d.detail;
      }
      a.command = d.command;
      break;
    }
  }
  if (a.problem.empty()) a.fingerprint = EdgeIntake::fingerprint(data, size);
  return a;
}

ControlCommand controlCommand(const command_t& c) {
  using Kind = ControlCommand::Kind;
  ControlCommand out;
  out.code = c.command;
  out.utime = c.utime;
  out.path = c.path;
  switch (c.command) {
    case command_t::REFINE:
      out.kind = Kind::kRefine;
      break;
    case command_t::PUBLISH_FULL:
      out.kind = Kind::kPublishFull;
      break;
    case command_t::SNAPSHOT:
      out.kind = Kind::kSnapshot;
      break;
    case command_t::STATUS:
      out.kind = Kind::kStatus;
      break;
    case command_t::BATCH:
      out.kind = Kind::kBatch;
      break;
    case command_t::CLOSURES:
      out.kind = Kind::kClosures;
      break;
    case command_t::COVARIANCE:
      out.kind = Kind::kCovariance;
      try {
        out.ids = covarianceIds(c.path);  // throws on anything but one or two ids
      } catch (const std::exception& e) {
        out.ids_problem = e.what();
      }
      break;
    default:
      out.kind = Kind::kUnknown;
  }
  return out;
}

estimate_t toMessage(const Estimate& e) {
  estimate_t m;
  m.utime = e.utime;
  m.last_sender = e.last_sender;
  m.last_seq = e.last_seq;
  m.update = e.update;
  m.full = e.full;
  m.dim = static_cast<std::int8_t>(e.dim);
  m.total_poses = e.total_poses;
  m.F = e.F;
  m.num_poses = e.num_poses;
  m.ids = e.ids;
  m.translation = e.translation;
  m.rotation = e.rotation;
  return m;
}

Estimate fromMessage(const estimate_t& m) {
  Estimate e;
  e.utime = m.utime;
  e.last_sender = m.last_sender;
  e.last_seq = m.last_seq;
  e.update = m.update;
  e.full = m.full != 0;
  e.dim = m.dim;
  e.total_poses = m.total_poses;
  e.F = m.F;
  e.num_poses = m.num_poses;
  e.ids = m.ids;
  e.translation = m.translation;
  e.rotation = m.rotation;
  return e;
}

covariance_t toMessage(const CovarianceAnswer& a) {
  covariance_t m;
  m.utime = nowMicros();
  m.request = a.request;
  m.ids = a.ids;
  m.num_ids = static_cast<std::int32_t>(a.ids.size());
  m.update = a.update;
  m.error = a.error;
  m.dim = a.error.empty() ? static_cast<std::int32_t>(a.matrix.rows()) : 0;
  m.matrix.assign(m.dim, std::vector<double>(m.dim));
  for (int r = 0; r < m.dim; ++r)
    for (int k = 0; k < m.dim; ++k) m.matrix[r][k] = a.matrix(r, k);
  return m;
}

status_t toMessage(const CoreStatus& k) {
  status_t s;
  s.utime = k.utime;
  const IntakeCounts& c = k.edges;
  s.received = c.received;
  s.accepted = c.accepted;
  s.rejected = c.rejected;
  s.duplicates = c.duplicates;
  s.gaps = c.gaps;
  for (const auto& [reason, count] : c.rejected_by_reason) {
    s.reason.push_back(reason);
    s.reason_count.push_back(count);
  }
  const IntakeCounts& p = k.priors;
  s.priors_received = p.received;
  s.priors_accepted = p.accepted;
  s.priors_rejected = p.rejected;
  s.priors_duplicates = p.duplicates;
  s.priors_gaps = p.gaps;
  for (const auto& [reason, count] : p.rejected_by_reason) {
    s.reason.push_back("prior " + reason);
    s.reason_count.push_back(count);
  }
  const IntakeCounts& c2 = k.commands;
  s.commands_received = c2.received;
  s.commands_accepted = c2.accepted;
  s.commands_rejected = c2.rejected;
  s.commands_duplicates = c2.duplicates;
  for (const auto& [reason, count] : c2.rejected_by_reason) {
    s.reason.push_back("command " + reason);
    s.reason_count.push_back(count);
  }
  s.control_refused = 0;
  for (const auto& [reason, count] : k.control_refused) {
    s.reason.push_back("control " + reason);
    s.reason_count.push_back(count);
    s.control_refused += count;
  }
  s.journal_refused = k.journal_refused;
  const auto by = [](const IntakeCounts& counts, const char* reason) {
    const auto it = counts.rejected_by_reason.find(reason);
    return it == counts.rejected_by_reason.end() ? std::int64_t{0} : it->second;
  };
  s.datagrams_refused = 0;
  for (const auto& [reason, count] : k.transport.datagrams_refused) {
    s.reason.push_back("datagram " + reason);
    s.reason_count.push_back(count);
    s.datagrams_refused += count;
  }
  s.auth_refused = 0;
  for (const auto& [reason, count] : k.transport.auth_refused) {
    s.reason.push_back("auth " + reason);
    s.reason_count.push_back(count);
    s.auth_refused += count;
  }
  s.refused_senders = by(c, "sender limit") + by(p, "sender limit") + by(c2, "sender limit");
  s.refused_oversize = by(c, "oversize") + by(p, "oversize") + by(c2, "oversize");
  if (const auto it = k.control_refused.find("oversize"); it != k.control_refused.end()) {
    s.refused_oversize += it->second;
  }
  s.senders = static_cast<int32_t>(k.edge_senders);
  s.receive_link_up = k.transport.receive_up;
  s.publish_link_up = k.transport.publish_up;
  s.link_outages = static_cast<int32_t>(k.transport.link_outages);
  s.publish_failures = k.transport.publish_failures;
  s.journal_bytes = k.journal_bytes;
  s.applied = k.applied;
  s.rejected += k.smoother_rejected;
  if (k.smoother_rejected > 0) {
    s.reason.push_back("smoother");
    s.reason_count.push_back(k.smoother_rejected);
  }
  s.priors_applied = k.priors_applied;
  s.priors_rejected += k.smoother_priors_rejected;
  if (k.smoother_priors_rejected > 0) {
    s.reason.push_back("prior smoother");
    s.reason_count.push_back(k.smoother_priors_rejected);
  }
  s.components = k.components;
  s.commands_applied = k.commands_applied;
  s.commands_refused = k.commands_refused;
  for (const auto& [reason, count] : k.command_refusals) {
    s.reason.push_back("command refused " + reason);
    s.reason_count.push_back(count);
  }
  s.edges_disabled = k.edges_disabled;
  s.pairs_disabled = k.pairs_disabled;
  s.last_command_sender = k.last_command_sender;
  s.last_command_seq = k.last_command_seq;
  s.last_command_result = k.last_command_result;
  s.duplicates += k.smoother_duplicates;
  s.pending = k.pending;
  s.updates = k.updates;
  s.queue_depth = static_cast<int32_t>(s.accepted + s.priors_accepted + s.commands_accepted -
                                       k.applied - k.priors_applied - k.commands_applied);
  s.held = k.held;
  s.poses = static_cast<int32_t>(k.poses);
  s.F = k.F;
  s.num_reasons = static_cast<int32_t>(s.reason.size());
  s.latency_window = k.latency_window;
  s.latency_p50_ms = k.latency.p50;
  s.latency_p99_ms = k.latency.p99;
  s.latency_max_ms = k.latency.max;
  s.refinements = k.refinements;
  s.refine_F_before = k.refine_F_before;
  s.refine_F_after = k.refine_F_after;
  s.refine_time_s = k.refine_time_s;
  const refine::BatchRun& last = k.last_batch;
  s.batches = k.batches;
  s.batches_skipped = k.batches_skipped;
  s.reseeds = k.reseeds;
  s.batch_update = last.update;
  s.batch_poses = last.poses;
  s.batch_F_incremental = last.F_incremental;
  s.batch_F = last.F_batch;
  s.batch_F_lm = last.F_lm;
  s.batch_relative_gap = last.relative_gap;
  s.batch_max_translation_diff = last.max_translation_diff;
  s.batch_max_rotation_diff = last.max_rotation_diff;
  s.batch_winner = last.winner;
  s.batch_margin = last.margin;
  s.batch_certified = last.certified;
  s.batch_rank = last.rank;
  s.batch_lambda_min = last.lambda_min;
  s.batch_time_s = last.time_s;
  s.batch_reseeded = last.reseeded;
  s.robust = k.robust;
  const OnlineStats& r = k.robust_stats;
  s.closures_inlier = r.closures_inlier;
  s.closures_outlier = r.closures_outlier;
  s.closures_trusted = r.closures_trusted;
  s.closures_excluded = r.closures_excluded;
  s.closures_graduating = r.closures_graduating;
  s.closures_total =
      r.closures_inlier + r.closures_outlier + r.closures_trusted + r.closures_excluded;
  s.inlier_threshold = k.inlier_threshold;
  s.batch_cancelled = last.cancelled;
  s.recv_buf_bytes = k.transport.recv_buf_bytes;
  // The senders with the most gaps, most first (ties: lower sender first), at most 16.
  std::vector<std::pair<std::int64_t, std::int64_t>> gaps = k.edge_gaps_by_sender;
  std::stable_sort(gaps.begin(), gaps.end(),
                   [](const auto& a, const auto& b) { return a.second > b.second; });
  constexpr int kListed = static_cast<int>(sizeof(s.gap_sender) / sizeof(s.gap_sender[0]));
  s.loss_held = k.loss.held;
  s.loss_reordered = k.loss.reordered;
  s.loss_given_up = k.loss.given_up;
  s.loss_late = k.loss.late;
  s.resend_requests = k.loss.requests;
  s.backlog_dropped = k.backlog_dropped;
  s.gap_senders = static_cast<std::int32_t>(std::min<size_t>(gaps.size(), kListed));
  for (int k2 = 0; k2 < kListed; ++k2) {
    const bool listed = k2 < s.gap_senders;
    s.gap_sender[k2] = listed ? gaps[static_cast<size_t>(k2)].first : 0;
    s.gap_count[k2] = listed ? gaps[static_cast<size_t>(k2)].second : 0;
  }
  return s;
}

}  // namespace arbor::serve
