// The synthetic-graph generator: deterministic by seed, consistent with its ground truth, and
// the graphs committed in data/ are exactly what it generates.
#include <filesystem>
#include <fstream>
#include <sstream>

#include <gtest/gtest.h>

#include "arbor_slam/core/batch_solver.h"
#include "arbor_slam/io/pose_graph_file.h"
#include "arbor_slam/tools/generator/graph_generator.h"

namespace arbor {
namespace {

TEST(Generator, SameSeedSameGraphOtherSeedOtherGraph) {
  sim::ManhattanOptions o;
  o.poses = 300;
  o.grid = 6;
  const auto a = sim::manhattanWorld(o), b = sim::manhattanWorld(o);
  o.seed = 2;
  const auto c = sim::manhattanWorld(o);
  std::ostringstream sa, sb, sc;
  writeG2o(sa, a.graph, a.graph.poses);
  writeG2o(sb, b.graph, b.graph.poses);
  writeG2o(sc, c.graph, c.graph.poses);
  EXPECT_EQ(sa.str(), sb.str());
  EXPECT_NE(sa.str(), sc.str());
}

TEST(Generator, ManhattanHasLoopClosuresAndTruthScoresLikeNoise) {
  sim::ManhattanOptions o;
  o.poses = 1000;
  const auto s = sim::manhattanWorld(o);
  EXPECT_EQ(s.graph.numPoses(), 1000);
  EXPECT_GT(s.graph.numEdges(), 1000 + 100);  // odometry plus a good number of closures
  // At the truth, e ~ N(0, Ω⁻¹): F ≈ χ² with 3 m degrees of freedom.
  const double F = objective(s.graph, s.truth);
  const double dof = 3.0 * s.graph.numEdges();
  EXPECT_NEAR(F / dof, 1.0, 0.1);
  // The optimum is close to the truth and far below the odometry start.
  auto poses = s.graph.poses;
  const BatchSummary summary = solveBatch(s.graph, &poses);
  EXPECT_LT(summary.F_final, F);
  EXPECT_LT(summary.F_final, 0.01 * summary.F_initial);
}

TEST(Generator, SphereAndGridAre3DWithClosures) {
  sim::SphereOptions so;
  so.rings = 5;
  so.poses_per_ring = 10;
  const auto sphere = sim::sphereWorld(so);
  EXPECT_EQ(sphere.graph.numPoses(), 50);
  EXPECT_EQ(sphere.graph.numEdges(), 49 + 40);
  sim::GridOptions go;
  go.poses = 400;
  go.size = 4;
  const auto grid = sim::gridWorld(go);
  EXPECT_EQ(grid.graph.numPoses(), 400);
  EXPECT_GT(grid.graph.numEdges(), 450);
  for (const auto* s : {&sphere, &grid}) {
    EXPECT_NEAR(objective(s->graph, s->truth) / (6.0 * s->graph.numEdges()), 1.0, 0.2);
  }
}

// data/ holds graphs this generator makes; regenerating them must give the same bytes
// (see data/README.md for the commands).
TEST(Generator, CommittedDataMatchesGenerator) {
  const std::string dir = std::string(ARBOR_SOURCE_DIR) + "/data/";
  auto fileText = [](const std::string& path) {
    std::ifstream in(path);
    std::stringstream s;
    s << in.rdbuf();
    return s.str();
  };
  sim::ManhattanOptions m;
  m.poses = 1500;
  m.grid = 20;
  m.seed = 1;
  sim::SphereOptions sp;
  sp.rings = 10;
  sp.poses_per_ring = 25;
  sp.seed = 1;
  sim::GridOptions gr;
  gr.poses = 500;
  gr.size = 5;
  gr.seed = 1;
  std::ostringstream a, b, c;
  const auto ms = sim::manhattanWorld(m);
  const auto ss = sim::sphereWorld(sp);
  const auto gs = sim::gridWorld(gr);
  writeG2o(a, ms.graph, ms.graph.poses);
  writeG2o(b, ss.graph, ss.graph.poses);
  writeG2o(c, gs.graph, gs.graph.poses);
  EXPECT_EQ(fileText(dir + "manhattan_2d.g2o"), a.str());
  EXPECT_EQ(fileText(dir + "sphere_3d.g2o"), b.str());
  EXPECT_EQ(fileText(dir + "grid_3d.g2o"), c.str());
}

}  // namespace
}  // namespace arbor
