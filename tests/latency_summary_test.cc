// Per-update latency figures (core/latency_summary.h): nearest-rank percentiles, and the first and
// last tenth of a run in its order (issue 17's flatness figure).
#include <vector>

#include <gtest/gtest.h>

#include "arbor_slam/core/latency_summary.h"

namespace arbor {
namespace {

TEST(LatencySummary, NearestRankPercentiles) {
  std::vector<double> ms;
  for (int k = 100; k >= 1; --k) ms.push_back(k);  // 100 .. 1, out of order
  const LatencySummary s = summarizeLatency(ms);
  EXPECT_EQ(s.p50, 50);
  EXPECT_EQ(s.p90, 90);
  EXPECT_EQ(s.p99, 99);
  EXPECT_EQ(s.max, 100);
  const LatencySummary none = summarizeLatency({});
  EXPECT_EQ(none.p99, 0);
}

// A run whose updates grow: the tenths are taken in the run's order, not after sorting.
TEST(LatencySummary, TenthsFollowTheRunsOrder) {
  std::vector<double> ms;
  for (int k = 0; k < 1000; ++k) ms.push_back(k < 100 ? 1.0 + 0.01 * k : 10.0 + 0.01 * k);
  ms[50] = 500;  // one slow update early on
  const TenthsSummary t = summarizeTenths(ms);
  EXPECT_DOUBLE_EQ(t.first.max, 500);
  EXPECT_DOUBLE_EQ(t.first.p50, 1.0 + 0.01 * 49);  // rank 50 of the first 100: 500 sorts last
  EXPECT_DOUBLE_EQ(t.last.p50, 10.0 + 0.01 * 949);
  EXPECT_DOUBLE_EQ(t.last.max, 10.0 + 0.01 * 999);
  EXPECT_DOUBLE_EQ(t.last.p99, 10.0 + 0.01 * 998);
  // Under ten updates both tenths are the whole run; none gives zeros.
  const TenthsSummary few = summarizeTenths({3, 1, 2});
  EXPECT_EQ(few.first.max, 3);
  EXPECT_EQ(few.last.p50, 2);
  EXPECT_EQ(summarizeTenths({}).last.p99, 0);
}

}  // namespace
}  // namespace arbor
