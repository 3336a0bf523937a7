// The poses an update changed (bayestree/updated_poses.h): each once, in increasing order, the
// poses moved before the update among them; every variable after noteAll.
#include <vector>

#include <gtest/gtest.h>

#include "arbor_slam/bayestree/updated_poses.h"

namespace arbor {
namespace {

using bayestree::UpdatedPoses;

UpdatedPoses withPoses(int n) {
  UpdatedPoses u;
  for (int v = 0; v < n; ++v) u.addPose();
  return u;
}

TEST(UpdatedPoses, EachPoseOnceInIncreasingOrder) {
  UpdatedPoses u = withPoses(6);
  u.begin();
  for (int v : {4, 1, 4, 3, 1}) u.note(v);
  u.finish(std::vector<char>(6, 0));
  EXPECT_EQ(u.inOrder(), (std::vector<int>{1, 3, 4}));
}

TEST(UpdatedPoses, MovedPosesJoinTheNextUpdateOnly) {
  UpdatedPoses u = withPoses(5);
  u.moved({2, 0});
  u.begin();
  u.note(2);
  u.finish(std::vector<char>(5, 0));
  EXPECT_EQ(u.inOrder(), (std::vector<int>{0, 2}));
  u.begin();
  u.note(3);
  u.finish(std::vector<char>(5, 0));
  EXPECT_EQ(u.inOrder(), std::vector<int>{3});
}

TEST(UpdatedPoses, NoteAllListsEveryPoseNotFixed) {
  UpdatedPoses u = withPoses(4);
  u.begin();
  u.note(2);
  u.noteAll();
  u.finish({1, 0, 0, 0});
  EXPECT_EQ(u.inOrder(), (std::vector<int>{1, 2, 3}));
  u.begin();  // a new update starts empty
  u.finish({1, 0, 0, 0});
  EXPECT_TRUE(u.inOrder().empty());
}

}  // namespace
}  // namespace arbor
