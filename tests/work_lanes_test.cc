// Tests of bayestree/work_lanes.h: every item worked exactly once, children before parents,
// exceptions carried back to the caller, many short walks in a row.

#include <atomic>
#include <random>
#include <stdexcept>
#include <vector>

#include "arbor_slam/bayestree/work_lanes.h"

#include <gtest/gtest.h>

namespace arbor::bayestree {
namespace {

// A random forest: parent[k] > k or −1.
std::vector<int> randomForest(int n, unsigned seed) {
  std::mt19937 rng(seed);
  std::vector<int> parent(n, -1);
  for (int k = 0; k + 1 < n; ++k) {
    std::uniform_int_distribution<int> pick(k + 1, std::min(n - 1, k + 8));
    if (rng() % 17 != 0) parent[k] = pick(rng);
  }
  return parent;
}

// Bottom-up: a node's value is one plus the sum of its children's, computed when the last
// child is done (as the Bayes tree's elimination); returns the values.
std::vector<long> subtreeSizes(WorkLanes* lanes, const std::vector<int>& parent,
                               std::vector<int>* worked_on_lane) {
  const int n = static_cast<int>(parent.size());
  std::vector<long> value(n, 0);
  std::vector<std::atomic<int>> left(n);
  std::vector<std::vector<int>> children(n);
  for (int k = 0; k < n; ++k)
    if (parent[k] >= 0) children[parent[k]].push_back(k);
  std::vector<int> leaves;
  for (int k = 0; k < n; ++k) {
    left[k] = static_cast<int>(children[k].size());
    if (children[k].empty()) leaves.push_back(k);
  }
  worked_on_lane->assign(n, -1);
  lanes->run(leaves, [&](int lane, int k) {
    EXPECT_EQ((*worked_on_lane)[k], -1) << "item " << k << " worked twice";
    (*worked_on_lane)[k] = lane;
    long v = 1;
    for (int c : children[k]) v += value[c];  // children done: their values are final
    for (volatile int spin = 0; spin < 200; ++spin) {
    }
    value[k] = v;
    const int p = parent[k];
    return p >= 0 && left[p].fetch_sub(1) == 1 ? p : -1;
  });
  return value;
}

TEST(WorkLanes, BottomUpWalkMatchesOneLane) {
  const std::vector<int> parent = randomForest(3000, 5);
  WorkLanes one(1);
  std::vector<int> lane_of;
  const std::vector<long> expected = subtreeSizes(&one, parent, &lane_of);
  long roots_total = 0;
  for (int k = 0; k < 3000; ++k)
    if (parent[k] < 0) roots_total += expected[k];
  EXPECT_EQ(roots_total, 3000);
  for (int lanes : {2, 3, 4}) {
    WorkLanes many(lanes);
    EXPECT_EQ(many.lanes(), lanes);
    for (int round = 0; round < 5; ++round) {
      EXPECT_EQ(subtreeSizes(&many, parent, &lane_of), expected) << lanes << " lanes";
      for (int l : lane_of) EXPECT_GE(l, 0);
    }
  }
}

TEST(WorkLanes, TopDownWalkWithPushReachesEveryNodeOnce) {
  const int n = 2000;
  const std::vector<int> parent = randomForest(n, 9);
  std::vector<std::vector<int>> children(n);
  std::vector<int> roots;
  for (int k = 0; k < n; ++k) (parent[k] >= 0 ? children[parent[k]] : roots).push_back(k);
  std::vector<long> depth(n, -1);
  WorkLanes lanes(2);
  for (int round = 0; round < 20; ++round) {
    std::vector<std::atomic<int>> visits(n);
    lanes.run(roots, [&](int, int k) {
      ++visits[k];
      depth[k] = parent[k] < 0 ? 0 : depth[parent[k]] + 1;  // the parent is done
      int next = -1;
      for (int c : children[k]) {
        if (next >= 0) lanes.push(next);
        next = c;
      }
      return next;
    });
    for (int k = 0; k < n; ++k) ASSERT_EQ(visits[k].load(), 1) << "node " << k;
  }
  for (int k = 0; k < n; ++k)
    EXPECT_EQ(depth[k], parent[k] < 0 ? 0 : depth[parent[k]] + 1) << "node " << k;
}

TEST(WorkLanes, ManyShortWalksInARow) {
  WorkLanes lanes(2);
  std::atomic<long> sum{0};
  for (int walk = 0; walk < 20000; ++walk) {
    lanes.run({walk % 3, 7}, [&](int, int k) {
      sum += k;
      if (k == 7) lanes.push(1);
      return -1;
    });
  }
  long expected = 0;
  for (int walk = 0; walk < 20000; ++walk) expected += walk % 3 + 7 + 1;
  EXPECT_EQ(sum.load(), expected);
}

TEST(WorkLanes, ExceptionReachesTheCallerAndLanesStayUsable) {
  WorkLanes lanes(2);
  std::vector<int> items(100);
  for (int k = 0; k < 100; ++k) items[k] = k;
  EXPECT_THROW(lanes.run(items,
                         [](int, int k) -> int {
                           if (k == 42) throw std::runtime_error("item 42");
                           return -1;
                         }),
               std::runtime_error);
  std::atomic<int> count{0};
  lanes.run(items, [&](int, int) {
    ++count;
    return -1;
  });
  EXPECT_EQ(count.load(), 100);
}

// A walk kept on the calling thread that throws must leave the lanes as they were: the next
// shared walk still pools what it pushes (and so reaches every item).
TEST(WorkLanes, ExceptionInAWalkKeptOnTheCallerLeavesSharingIntact) {
  WorkLanes lanes(2);
  EXPECT_THROW(lanes.run(
                   {1, 2, 3},
                   [&](int, int k) -> int {
                     if (k == 2) throw std::runtime_error("item 2");
                     if (k < 10) lanes.push(10 + k);  // 3 pushes 13, a leaf; then 2 throws
                     return -1;
                   },
                   /*share=*/false),
               std::runtime_error);
  std::atomic<int> count{0};
  lanes.run({0}, [&](int, int k) {
    ++count;
    if (k < 50) {
      lanes.push(2 * k + 1);
      lanes.push(2 * k + 2);
    }
    return -1;
  });
  EXPECT_EQ(count.load(), 101);  // 0..100: a binary tree, every item once
}

TEST(WorkLanes, RejectsZeroLanes) { EXPECT_THROW(WorkLanes(0), std::invalid_argument); }

}  // namespace
}  // namespace arbor::bayestree
