// io/edge_choice_file.h: the sidecar of per-edge robust choices (trust, kernel) — parsing, bad
// lines named by place and value, pairs the graph does not have — and `arbor replay --robust
// --edge-choices`: a planted false closure marked trusted keeps weight 1, a false second
// odometry edge marked robust is judged and rejected.
#include <cstdlib>
#include <set>
#include <sstream>
#include <string>

#include <gtest/gtest.h>

#include "arbor_slam/core/gnc_solver.h"
#include "arbor_slam/core/initialization.h"
#include "arbor_slam/io/edge_choice_file.h"
#include "arbor_slam/tools/cli/replay_runner.h"
#include "arbor_slam/tools/generator/graph_generator.h"

namespace arbor {
namespace {

EdgeChoices parse(const std::string& text) {
  std::istringstream in(text);
  return readEdgeChoices(in, "x.choices");
}

void refused(const std::string& text, const std::string& named) {
  try {
    parse(text);
    ADD_FAILURE() << "accepted: " << text;
  } catch (const FileError& e) {
    EXPECT_NE(std::string(e.what()).find(named), std::string::npos) << e.what();
  }
}

TEST(EdgeChoiceFile, ReadsTrustAndKernelEitherDirection) {
  const EdgeChoices c = parse(
      "# comment\n\n10 90 trusted\n61 60 robust cauchy  # odometry it doubts\n5 40 default gm\n");
  ASSERT_EQ(c.size(), 3u);
  EXPECT_EQ(edgeChoice(c, 90, 10).trust, EdgeTrust::kTrusted);
  EXPECT_EQ(edgeChoice(c, 10, 90).kernel, KernelKind::kNone);
  EXPECT_EQ(edgeChoice(c, 60, 61).trust, EdgeTrust::kRobust);
  EXPECT_EQ(edgeChoice(c, 60, 61).kernel, KernelKind::kCauchy);
  EXPECT_EQ(edgeChoice(c, 5, 40).trust, EdgeTrust::kByRule);
  EXPECT_EQ(edgeChoice(c, 5, 40).kernel, KernelKind::kGemanMcClure);
  EXPECT_EQ(edgeChoice(c, 1, 2).trust, EdgeTrust::kByRule);  // not listed: the rules
}

TEST(EdgeChoiceFile, BadLinesAreNamedByPlaceAndValue) {
  refused("1 2 sure\n", "x.choices:1: trust 'sure'");
  refused("1 2\n", "x.choices:1: expected 'FROM TO TRUST [KERNEL]'");
  refused("\n1 2 trusted welsch\n", "x.choices:2: kernel 'welsch'");
  refused("1 2 trusted none\n", "kernel 'none'");
  refused("-1 2 trusted\n", "pose id '-1'");
  refused("3 3 robust\n", "self-loop 3");
  refused("1 2 trusted\n2 1 robust\n",
          "x.choices:2: a second choice for 2 1 (the first is on line 1)");
  sim::ManhattanOptions o;
  o.poses = 20;
  const PoseGraph2 graph = sim::manhattanWorld(o).graph;
  try {
    checkEdgeChoices(parse("0 1 trusted\n3 17 trusted\n"), graph, "x.choices");
    ADD_FAILURE() << "3 17 has no edge";
  } catch (const FileError& e) {
    EXPECT_NE(std::string(e.what()).find("x.choices:2: 3 17 names no edge"), std::string::npos)
        << e.what();
  }
}

TEST(EdgeChoiceFile, ReplayTakesTheChoicePerEdge) {
  sim::ManhattanOptions o;
  o.poses = 120;
  o.grid = 4;
  o.seed = 5;
  PoseGraph2 graph = sim::manhattanWorld(o).graph;
  RelativePoseEdge<SE2> wrong = graph.edges.back();
  wrong.i = 10;
  wrong.j = 90;
  wrong.measurement = SE2(0.5, 0.2, 0.1);
  graph.edges.push_back(wrong);
  wrong.i = 60;
  wrong.j = 61;
  wrong.measurement = SE2(3.0, -2.0, 1.0);
  graph.edges.push_back(wrong);
  cli::ReplaySettings settings;
  settings.robust = RobustOptions{};
  settings.batch = false;
  auto statuses = [&](const cli::ReplayResult<SE2>& r, Key i, Key j) {
    std::set<ClosureStatus> out;
    for (const ClosureReport& c : r.closures)
      if (c.from == i && c.to == j) out.insert(c.status);
    return out;
  };
  using Set = std::set<ClosureStatus>;
  const cli::ReplayResult<SE2> plain = cli::runReplay(graph, settings);
  EXPECT_EQ(statuses(plain, 10, 90), Set{ClosureStatus::kOutlier});
  EXPECT_EQ(statuses(plain, 60, 61), Set{});  // odometry: not judged
  settings.choices = parse("10 90 trusted\n60 61 robust\n");
  checkEdgeChoices(settings.choices, graph, "x.choices");
  const cli::ReplayResult<SE2> chosen = cli::runReplay(graph, settings);
  EXPECT_EQ(statuses(chosen, 10, 90), Set{ClosureStatus::kTrusted});
  // Both 60 -> 61 edges are robust now: the true one created pose 61 (structural, trusted), the
  // false one is judged and rejected.
  EXPECT_EQ(statuses(chosen, 60, 61), (Set{ClosureStatus::kTrusted, ClosureStatus::kOutlier}));
}

// The robust batch (arbor batch --robust --edge-choices): the same sidecar into GNC's per-edge
// trust and kernels; a false closure marked trusted is kept at weight 1, a false second
// odometry edge marked robust is judged and rejected, a closure's own kernel reaches the GNC.
TEST(EdgeChoiceFile, BatchTakesTheChoicePerEdge) {
  sim::ManhattanOptions o;
  o.poses = 120;
  o.grid = 4;
  o.seed = 5;
  PoseGraph2 graph = sim::manhattanWorld(o).graph;
  int closure = -1;
  for (int k = 0; k < graph.numEdges() && closure < 0; ++k)
    if (std::abs(graph.edges[k].i - graph.edges[k].j) > 1) closure = k;
  ASSERT_GE(closure, 0);
  RelativePoseEdge<SE2> wrong = graph.edges.back();
  wrong.i = 10;
  wrong.j = 90;
  wrong.measurement = SE2(0.5, 0.2, 0.1);
  graph.edges.push_back(wrong);
  const int trusted_false = graph.numEdges() - 1;
  wrong.i = 60;
  wrong.j = 61;
  wrong.measurement = SE2(3.0, -2.0, 1.0);
  graph.edges.push_back(wrong);
  const int robust_false = graph.numEdges() - 1;
  const Key ci = graph.ids[graph.edges[closure].i], cj = graph.ids[graph.edges[closure].j];
  const EdgeChoices choices = parse("10 90 trusted\n60 61 robust\n" + std::to_string(ci) + " " +
                                    std::to_string(cj) + " default huber\n");
  checkEdgeChoices(choices, graph, "x.choices");
  GncOptions gnc;
  applyEdgeChoices(choices, graph, &gnc);
  EXPECT_FALSE(gnc.trust_odometry);
  ASSERT_EQ(static_cast<int>(gnc.trusted.size()), graph.numEdges());
  EXPECT_EQ(gnc.kernels[closure], KernelKind::kHuber);
  EXPECT_FALSE(gnc.trusted[closure]);
  EXPECT_TRUE(gnc.trusted[trusted_false]);
  EXPECT_FALSE(gnc.trusted[robust_false]);
  EXPECT_TRUE(gnc.trusted[0]);  // odometry by the rule
  std::vector<SE2> poses = initialize(graph, InitMethod::kOdometry);
  const GncResult r = solveGnc(graph, &poses, gnc);
  EXPECT_EQ(r.weights[trusted_false], 1.0);
  EXPECT_TRUE(r.inlier[trusted_false]);
  EXPECT_FALSE(r.inlier[robust_false]);
  int judged_odometry = 0;
  for (int k = 0; k < graph.numEdges(); ++k) {
    const auto& e = graph.edges[k];
    if (k != robust_false && std::abs(e.i - e.j) == 1 && graph.ids[e.i] + graph.ids[e.j] == 121) {
      EXPECT_FALSE(r.trusted[k]);  // the true 60 -> 61 is judged too
      ++judged_odometry;
    }
  }
  EXPECT_EQ(judged_odometry, 1);
}

}  // namespace
}  // namespace arbor
