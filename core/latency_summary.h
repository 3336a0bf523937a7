// Per-update latency figures: nearest-rank percentiles of a sample of durations (or of any
// counts). Shared by the replay, the streaming service and the benchmarks.
#pragma once

#include <algorithm>
#include <cmath>
#include <vector>

namespace arbor {

struct LatencySummary {
  double p50 = 0, p90 = 0, p99 = 0, max = 0;  ///< milliseconds
};

/// Nearest-rank percentiles of `ms` (copied and sorted).
inline LatencySummary summarizeLatency(std::vector<double> ms) {
  LatencySummary s;
  if (ms.empty()) return s;
  std::sort(ms.begin(), ms.end());
  auto pct = [&](double p) {
    const size_t rank = static_cast<size_t>(std::ceil(p / 100.0 * ms.size()));
    return ms[std::min(ms.size() - 1, rank == 0 ? 0 : rank - 1)];
  };
  s.p50 = pct(50);
  s.p90 = pct(90);
  s.p99 = pct(99);
  s.max = ms.back();
  return s;
}

/// The percentiles of the first and of the last tenth of `ms` in its order (issue 17's flatness:
/// the last tenth's p99 within 2× of the first's). Fewer than ten samples: both of them all.
struct TenthsSummary {
  LatencySummary first, last;
};
inline TenthsSummary summarizeTenths(const std::vector<double>& ms) {
  const size_t n = ms.size(), tenth = std::max<size_t>(n / 10, n < 10 ? n : 1);
  return {summarizeLatency(std::vector<double>(ms.begin(), ms.begin() + tenth)),
          summarizeLatency(std::vector<double>(ms.end() - tenth, ms.end()))};
}

}  // namespace arbor
