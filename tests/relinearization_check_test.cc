// Fluid relinearisation's check (bayestree/relinearization_check.h): reading only the variables
// solved since the last check marks what a scan of every variable marks, in the same order;
// fixed variables and those not in the tree are never marked; a check consumes the candidates.
#include <random>
#include <vector>

#include <gtest/gtest.h>

#include "arbor_slam/bayestree/relinearization_check.h"
#include "arbor_slam/core/se2.h"
#include "arbor_slam/core/se3.h"

namespace arbor {
namespace {

using bayestree::RelinearizationCheck;

constexpr double kBeta = 0.1;

template <class G>
struct Poses {
  std::vector<typename G::Tangent> delta;
  std::vector<char> fixed;
  std::vector<int> clique_of;
  RelinearizationCheck<G> check;
  explicit Poses(int n) {
    for (int v = 0; v < n; ++v) {
      delta.push_back(G::Tangent::Zero());
      fixed.push_back(v == 0);
      clique_of.push_back(v == n - 1 ? -1 : 0);  // the last pose is not in the tree yet
      check.addPose();
    }
  }
  std::vector<int> mark(int* checked) {
    std::vector<int> out;
    *checked = check.mark(delta, fixed, clique_of, kBeta, kBeta, &out);
    return out;
  }
};

template <class G>
void candidatesMarkWhatAScanMarks() {
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> small(-0.05, 0.05), large(-0.3, 0.3);
  Poses<G> a(200), b(200);
  for (int round = 0; round < 5; ++round) {
    // A solve changes some Δ (and lists them); every other Δ stays below β.
    for (int v = 0; v < 200; ++v)
      if (v % 7 == round) {
        for (int k = 0; k < G::kDoF; ++k) a.delta[v][k] = b.delta[v][k] = large(rng);
        a.check.solved(v);
        a.check.solved(v);  // listed once
      } else if (round == 0) {
        for (int k = 0; k < G::kDoF; ++k) a.delta[v][k] = b.delta[v][k] = small(rng);
      }
    b.check.scanAll();
    int checked_a = 0, checked_b = 0;
    const std::vector<int> by_candidates = a.mark(&checked_a), by_scan = b.mark(&checked_b);
    EXPECT_EQ(by_candidates, by_scan) << round;
    EXPECT_FALSE(by_scan.empty());
    EXPECT_EQ(checked_b, 200);
    EXPECT_LT(checked_a, 40);
    for (int v : by_scan) {
      EXPECT_NE(v, 0);    // fixed
      EXPECT_NE(v, 199);  // not in the tree
      // Relinearised: Δ zero at the new point, below β from now on.
      a.delta[v].setZero();
      b.delta[v].setZero();
    }
  }
}

TEST(RelinearizationCheck, CandidatesMarkWhatAScanMarks2D) { candidatesMarkWhatAScanMarks<SE2>(); }
TEST(RelinearizationCheck, CandidatesMarkWhatAScanMarks3D) { candidatesMarkWhatAScanMarks<SE3>(); }

TEST(RelinearizationCheck, TranslationAndRotationEachAgainstTheirBeta) {
  SE2::Tangent dx = SE2::Tangent::Zero();
  dx[1] = 0.2;  // translational
  EXPECT_TRUE(RelinearizationCheck<SE2>::exceeds(dx, 0.1, 1.0));
  EXPECT_FALSE(RelinearizationCheck<SE2>::exceeds(dx, 0.3, 0.01));
  dx.setZero();
  dx[2] = 0.2;  // rotational
  EXPECT_TRUE(RelinearizationCheck<SE2>::exceeds(dx, 1.0, 0.1));
  EXPECT_FALSE(RelinearizationCheck<SE2>::exceeds(dx, 0.01, 0.3));
}

TEST(RelinearizationCheck, ACheckConsumesItsCandidates) {
  Poses<SE2> p(10);
  p.delta[4][0] = 1;
  p.check.solved(4);
  int checked = 0;
  EXPECT_EQ(p.mark(&checked), std::vector<int>{4});
  EXPECT_EQ(checked, 1);
  EXPECT_TRUE(p.mark(&checked).empty());  // not solved since: not checked again
  EXPECT_EQ(checked, 0);
  p.check.solved(4);
  p.check.consume();  // relinearised unchecked
  EXPECT_TRUE(p.mark(&checked).empty());
}

}  // namespace
}  // namespace arbor
