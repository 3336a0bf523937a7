// The noise scale on generated graphs of known scale (issue 52): small-loop worlds
// (tools/generator/road_world.h: 1,000 poses, about 100 loop closures, one closure in 20 drawn
// 6× wider with the same Ω) written with Ω = X times the information of the noise drawn, no
// false closures, replayed edge by edge through the robust online smoother with its defaults.
// The true closures' innovations are then σ²·χ²_d with σ² = X (noise_scale.h), so:
//   X = 1 (Ω right)            σ̂² near 1, or no estimate (Ω at its word, which is right);
//   X = 1/20 … 1/100 (cautious) σ̂² near X, the threshold moved down.
// Ω 20–50× over-confident (X = 20 … 50) is where the layer still fails (docs/design.md, "Where
// it still fails"): with about 100 closures, fewer than a quarter of them within the
// truncation at Ω's word, the loosening rule (noise_scale.h, "moves") refuses the estimate.
// "Near": within a factor 2 (the heavy tail and the truncation leave the core's scale,
// header comment "bias"). And in every world, at most the wide tail's closures rejected.
#include <cstdint>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "arbor_slam/bayestree/online_smoother.h"
#include "arbor_slam/tools/cli/replay_order.h"
#include "arbor_slam/tools/generator/road_world.h"

namespace arbor {
namespace {

template <class G>
OnlineStats replayWorld(const sim::Simulation<G>& world) {
  OnlineSmootherOptions<G> options;
  options.robust = RobustOptions{};
  OnlineSmoother<G> smoother(options);
  // Edge by edge in `arbor replay`'s order (tools/cli/replay_order.h).
  for (const auto& group : cli::replayGroups(world.graph, /*per_pose=*/false))
    for (const int k : group) {
      const auto& e = world.graph.edges[static_cast<size_t>(k)];
      const auto result =
          smoother.addEdge(world.graph.ids[static_cast<size_t>(e.i)],
                           world.graph.ids[static_cast<size_t>(e.j)], e.measurement, e.information);
      EXPECT_EQ(result.status, EdgeStatus::kAccepted) << "edge " << k;
      smoother.update();
    }
  smoother.finalize();
  return smoother.stats();
}

template <class G>
sim::Simulation<G> smallLoopWorld(double information_scale, std::uint64_t seed);
template <>
sim::Simulation<SE2> smallLoopWorld<SE2>(double information_scale, std::uint64_t seed) {
  sim::RoadOptions o = sim::smallLoopOptions();
  o.seed = seed;
  o.noise.information_scale = information_scale;
  return sim::roadWorld2(o);
}
template <>
sim::Simulation<SE3> smallLoopWorld<SE3>(double information_scale, std::uint64_t seed) {
  sim::RoadOptions o = sim::smallLoopOptions();
  o.seed = seed;
  o.noise.information_scale = information_scale;
  return sim::roadWorld3(o);
}

template <class G>
void scaleOfWorlds() {
  for (const double X : {1.0, 1.0 / 20, 1.0 / 100})
    for (const std::uint64_t seed : {1, 2}) {
      SCOPED_TRACE("X " + std::to_string(X) + " seed " + std::to_string(seed));
      const sim::Simulation<G> world = smallLoopWorld<G>(X, seed);
      const OnlineStats st = replayWorld(world);
      const int closures = st.closures_inlier + st.closures_outlier;
      ASSERT_GT(closures, 60);
      if (X == 1.0) {  // σ² = X: the true covariances are X·Ω⁻¹
        if (st.noise_scale_estimated) {
          EXPECT_GT(st.noise_scale, 0.5);
          EXPECT_LT(st.noise_scale, 2.0);
        }
      } else {
        ASSERT_TRUE(st.noise_scale_estimated);
        EXPECT_GT(st.noise_scale, 0.5 * X);
        EXPECT_LT(st.noise_scale, 2.0 * X);
      }
      // One closure in 20 is drawn 6× wider: about 5 here; nothing else is rejected.
      EXPECT_LE(st.closures_outlier, closures / 10);
    }
}

TEST(NoiseScaleWorlds, SmallLoop2D) { scaleOfWorlds<SE2>(); }
TEST(NoiseScaleWorlds, SmallLoop3D) { scaleOfWorlds<SE3>(); }

}  // namespace
}  // namespace arbor
