#include "arbor_slam/tools/cli/resend_window.h"

#include <algorithm>
#include <stdexcept>

namespace arbor::cli {

ResendWindow::ResendWindow(std::size_t capacity, std::int64_t sender)
    : capacity_(capacity), sender_(sender) {
  if (capacity < 1) throw std::invalid_argument("ResendWindow: capacity 0 is not >= 1");
}

void ResendWindow::sent(bool prior, std::int64_t seq, std::string channel,
                        std::vector<std::uint8_t> bytes, Clock::time_point now) {
  Stream& s = streams_[prior ? 1 : 0];
  if (!s.entries.empty() && seq != s.entries.back().seq + 1) s.entries.clear();  // not consecutive
  s.entries.push_back(Entry{seq, std::move(channel), std::move(bytes), now});
  s.last_sent = seq;
  while (s.entries.size() > capacity_) s.entries.pop_front();
}

ResendWindow::Entry* ResendWindow::find(Stream& s, std::int64_t seq) {
  if (s.entries.empty() || seq < s.entries.front().seq || seq > s.entries.back().seq)
    return nullptr;
  return &s.entries[static_cast<std::size_t>(seq - s.entries.front().seq)];
}

void ResendWindow::resend(Entry& e, Clock::time_point now, Answer& a) {
  if (now - e.sent < kMinInterval) return;
  e.sent = now;
  a.resend.push_back(&e);
  ++counts_.resent;
}

ResendWindow::Answer ResendWindow::request(const ResendMessage& m, Clock::time_point now) {
  Answer a;
  if (!m.request || m.sender != sender_) return a;
  ++counts_.requests;
  Stream& s = streams_[m.priors ? 1 : 0];
  s.settled = std::max(s.settled, m.settled);
  while (!s.entries.empty() && s.entries.front().seq <= s.settled) s.entries.pop_front();
  // The lowest seq held; below it nothing can be sent again.
  const std::int64_t floor = s.entries.empty() ? s.last_sent + 1 : s.entries.front().seq;
  for (const auto& [first, last] : m.missing) {
    if (first < floor) a.unavailable += std::min(last, floor - 1) - first + 1;
    const std::int64_t to = std::min(last, s.last_sent);
    for (std::int64_t seq = std::max(first, floor); seq <= to; ++seq) {
      if (Entry* e = find(s, seq)) resend(*e, now, a);
    }
  }
  if (finished_) {  // the tail serve has not seen
    for (std::int64_t seq = std::max(m.highest + 1, floor); seq <= s.last_sent; ++seq) {
      Entry* e = find(s, seq);
      if (e != nullptr && now - e->sent >= kTailAfter) resend(*e, now, a);
    }
  }
  counts_.unavailable += a.unavailable;
  if (a.unavailable > 0 && (!s.answered || now - s.last_window_answer >= kMinInterval)) {
    ResendMessage w;
    w.request = false;
    w.priors = m.priors;
    w.sender = sender_;
    w.settled = floor - 1;
    w.highest = std::max(s.last_sent, w.settled);
    a.window = w;
    s.answered = true;
    s.last_window_answer = now;
    ++counts_.window_answers;
  }
  return a;
}

bool ResendWindow::acknowledged(bool prior, std::int64_t last) const {
  return last <= 0 || streams_[prior ? 1 : 0].settled >= last;
}

std::vector<const ResendWindow::Entry*> ResendWindow::tailProbes(Clock::time_point now) {
  std::vector<const Entry*> out;
  if (!finished_) return out;
  for (Stream& s : streams_) {
    if (s.entries.empty() || s.settled >= s.last_sent) continue;
    Entry& e = s.entries.back();
    if (now - e.sent < kTailAfter) continue;
    e.sent = now;
    ++counts_.resent;
    out.push_back(&e);
  }
  return out;
}

}  // namespace arbor::cli
