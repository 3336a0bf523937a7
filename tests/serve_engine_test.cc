// Tests of the service's engine (tools/serve/serve_engine.h): the "changed" estimates, built from
// the smoother's updatedPoses, carry every pose whose published value changed.

#include <cstdio>
#include <fstream>
#include <map>
#include <random>
#include <string>
#include <vector>

#include "arbor_slam/tests/random_graphs.h"
#include "arbor_slam/tools/serve/serve_engine.h"

#include <gtest/gtest.h>

namespace arbor::serve {
namespace {

using testing::diagonalInformation;
using testing::isotropicNoise;

struct Published {
  std::vector<double> translation, rotation;
  bool operator==(const Published& o) const {
    return translation == o.translation && rotation == o.rotation;
  }
};

void apply(const Estimate& m, std::map<std::int64_t, Published>* state) {
  for (int k = 0; k < m.num_poses; ++k) (*state)[m.ids[k]] = {m.translation[k], m.rotation[k]};
}

// Applying the "changed" messages in turn gives, every few updates, exactly the full estimate: no
// pose whose value changed was left out, on a walk with loop closures (relinearisation steps,
// fold-ins and batch re-eliminations among its updates).
TEST(ServeEngine, ChangedMessagesAddUpToTheFullEstimate) {
  std::unique_ptr<Engine> engine = makeEngine(2, SmootherOptions{});
  std::mt19937 rng(7);
  std::vector<SE2> truth(1);
  std::map<std::int64_t, Published> state;
  const auto omega = diagonalInformation<SE2>(100.0, 400.0);
  auto send = [&](Key from, Key to) {
    StreamEdge<SE2> e;
    e.from = from;
    e.to = to;
    e.z = truth[from].between(truth[to]).compose(SE2::Exp(isotropicNoise<SE2>(rng, 0.05)));
    e.omega = omega;
    engine->add(AnyStreamEdge(e));
  };
  std::uniform_real_distribution<double> u(0.0, 1.0);
  int changed_total = 0;
  for (int k = 1; k <= 400; ++k) {
    SE2::Tangent step = isotropicNoise<SE2>(rng, 0.3);
    step(0) += 1.0;
    truth.push_back(truth.back().compose(SE2::Exp(step)));
    send(k - 1, k);
    if (k > 10 && u(rng) < 0.2) send(std::uniform_int_distribution<int>(0, k - 5)(rng), k);
    engine->update();
    const Estimate changed = engine->estimate(false);
    EXPECT_FALSE(changed.full);
    EXPECT_EQ(changed.total_poses, k + 1);
    changed_total += changed.num_poses;
    apply(changed, &state);
    if (k % 25 == 0) {
      const Estimate full = engine->estimate(true);
      ASSERT_EQ(full.num_poses, k + 1);
      std::map<std::int64_t, Published> expected;
      apply(full, &expected);
      for (const auto& [id, value] : expected) {
        const auto it = state.find(id);
        ASSERT_TRUE(it != state.end() && it->second == value)
            << "pose " << id << " after update " << k;
      }
      ASSERT_EQ(state.size(), expected.size());
    }
  }
  EXPECT_LT(changed_total, 400 * 401 / 2) << "fewer than every pose every time";
}

// TUM output of the service: a pose's time is the utime (µs, written in s) of the edge or prior
// that created it, not of later edges to it; g2o and KITTI are as before.
TEST(ServeEngine, TumTimesAreTheUtimeOfTheMeasurementThatCreatedEachPose) {
  std::unique_ptr<Engine> engine = makeEngine(2, SmootherOptions{});
  const auto omega = diagonalInformation<SE2>(100.0, 400.0);
  auto send = [&](Key from, Key to, std::int64_t utime) {
    StreamEdge<SE2> e;
    e.from = from;
    e.to = to;
    e.z = SE2(1.0, 0.0, 0.1);
    e.omega = omega;
    e.utime = utime;
    engine->add(AnyStreamEdge(e));
  };
  send(10, 11, 1'700'000'000'000'000);  // creates 10 and 11
  send(11, 12, 1'700'000'000'250'000);
  send(12, 13, 1'700'000'000'500'000);
  send(10, 13, 1'700'000'009'000'000);  // a loop closure: no new pose
  engine->update();
  const std::string path = ::testing::TempDir() + "serve_engine_stamps.tum";
  engine->writeEstimate(path, TrajectoryFormat::kTum);
  std::ifstream in(path);
  std::vector<double> times;
  std::string line;
  while (std::getline(in, line)) times.push_back(std::stod(line.substr(0, line.find(' '))));
  EXPECT_EQ(times, (std::vector<double>{1'700'000'000.0, 1'700'000'000.0, 1'700'000'000.25,
                                        1'700'000'000.5}));
  std::remove(path.c_str());
}

}  // namespace
}  // namespace arbor::serve
