// The LCM channels of `arbor serve` (docs/lcm.md's table), each after the --channel-prefix.
#pragma once

#include <set>
#include <string>

namespace arbor::serve {

struct Channels {
  std::string edges, estimate, status, command, priors, edge_commands;
  std::string link_probe;     ///< the receive link's own probe (LinkWatch)
  std::string covariance;     ///< answers to command COVARIANCE
  std::string resend;         ///< serve's resend requests (resend_t REQUEST)
  std::string resend_window;  ///< publishers' answers: what they no longer hold (resend_t WINDOW)
  /// ARBOR_EDGES, ARBOR_ESTIMATE, ARBOR_STATUS, ARBOR_COMMAND, ARBOR_PRIORS,
  /// ARBOR_EDGE_COMMANDS, ARBOR_LINK_PROBE, ARBOR_COVARIANCE, ARBOR_RESEND,
  /// ARBOR_RESEND_WINDOW, each after `prefix`.
  static Channels withPrefix(const std::string& prefix) {
    return {prefix + "ARBOR_EDGES",      prefix + "ARBOR_ESTIMATE",
            prefix + "ARBOR_STATUS",     prefix + "ARBOR_COMMAND",
            prefix + "ARBOR_PRIORS",     prefix + "ARBOR_EDGE_COMMANDS",
            prefix + "ARBOR_LINK_PROBE", prefix + "ARBOR_COVARIANCE",
            prefix + "ARBOR_RESEND",     prefix + "ARBOR_RESEND_WINDOW"};
  }
  /// The channels serve receives from others (what a udpm receiver reassembles): edges,
  /// priors, edge commands, commands and the publishers' resend answers.
  std::set<std::string> received() const {
    return {edges, priors, edge_commands, command, resend_window};
  }
};

/// The journal's own channels (inside the event log only).
inline constexpr const char* kJournalMarkChannel = "ARBOR_JOURNAL_MARK";
inline constexpr const char* kJournalReseedChannel = "ARBOR_JOURNAL_RESEED";

}  // namespace arbor::serve
