// The publisher's side of loss recovery (docs/lcm.md, "Loss recovery"): `arbor publish
// --resend-window N` keeps the last N messages it sent per stream (edges, priors), byte for byte,
// and answers serve's resend requests (resend_t REQUEST on ARBOR_RESEND) from them: the missing
// ranges, and once the whole stream is sent, what it sent above serve's highest (a lost tail).
// What was asked for and is no longer held (below the window, or never sent, e.g. before
// --skip) is answered with a WINDOW message, so serve gives those seq numbers up at once. A
// request's `settled` acknowledges the stream up to there: those messages leave the window.
// No LCM here (the command wires it); not thread-safe (the caller's lock).
#pragma once

#include <chrono>
#include <cstddef>
#include <cstdint>
#include <deque>
#include <optional>
#include <string>
#include <vector>

#include "arbor_slam/io/lcm_messages.h"

namespace arbor::cli {

class ResendWindow {
 public:
  using Clock = std::chrono::steady_clock;
  /// A message is sent again at most this often (a request repeated before its resend arrived
  /// does not double it).
  static constexpr std::chrono::milliseconds kMinInterval{150};
  /// After the stream: the tail above serve's highest is sent again once this old.
  static constexpr std::chrono::milliseconds kTailAfter{300};

  struct Entry {
    std::int64_t seq = 0;
    std::string channel;
    std::vector<std::uint8_t> bytes;  ///< as first sent (the message, before any envelope)
    Clock::time_point sent;
  };
  struct Answer {
    std::vector<const Entry*> resend;     ///< in seq order; valid until the next call
    std::optional<ResendMessage> window;  ///< a WINDOW answer to publish
    std::int64_t unavailable = 0;         ///< seq numbers asked for and not held
  };
  struct Counts {
    std::int64_t requests = 0;        ///< requests for this sender
    std::int64_t resent = 0;          ///< messages sent again
    std::int64_t window_answers = 0;  ///< WINDOW answers
    std::int64_t unavailable = 0;     ///< seq numbers asked for and not held
  };

  /// `capacity` >= 1 messages per stream.
  ResendWindow(std::size_t capacity, std::int64_t sender);

  void sent(bool prior, std::int64_t seq, std::string channel, std::vector<std::uint8_t> bytes,
            Clock::time_point now);
  /// Every message is sent: from now on the tail above serve's highest is sent again.
  void finished() { finished_ = true; }
  /// A request (`m.request`; another sender's, or a WINDOW message: nothing to do).
  Answer request(const ResendMessage& m, Clock::time_point now);
  /// Serve settled `prior`'s stream up to `last` (true when last <= 0: nothing to settle).
  bool acknowledged(bool prior, std::int64_t last) const;
  /// After finished(): the last message of each stream not yet acknowledged whose last sending
  /// is kTailAfter old (serve may have lost the tail and heard nothing since).
  std::vector<const Entry*> tailProbes(Clock::time_point now);
  Counts counts() const { return counts_; }
  std::int64_t settled(bool prior) const { return streams_[prior ? 1 : 0].settled; }

 private:
  struct Stream {
    std::deque<Entry> entries;  ///< consecutive seqs
    std::int64_t settled = 0;   ///< serve's acknowledgement
    std::int64_t last_sent = 0;
    Clock::time_point last_window_answer;
    bool answered = false;
  };
  Entry* find(Stream& s, std::int64_t seq);
  void resend(Entry& e, Clock::time_point now, Answer& a);

  std::size_t capacity_;
  std::int64_t sender_;
  bool finished_ = false;
  Stream streams_[2];  ///< edges, priors
  Counts counts_;
};

}  // namespace arbor::cli
