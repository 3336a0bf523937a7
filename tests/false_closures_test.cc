// False loop closures (tools/generator/false_closures.h): the count, each policy's geometry, the
// shared false transform of a group, the copied information, uniform rotations, determinism by
// seed, the labels and the g2o round trip, refused options; and that the same definitions
// describe the shared robust files (shared/datasets/robust/).
#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <set>
#include <sstream>

#include <gtest/gtest.h>

#include "arbor_slam/io/labels_file.h"
#include "arbor_slam/io/pose_graph_file.h"
#include "arbor_slam/tools/generator/false_closures.h"
#include "arbor_slam/tools/generator/graph_generator.h"
#include "shared_data.h"

namespace arbor {
namespace {

using sim::OutlierOptions;
using sim::OutlierPolicy;

const PoseGraph2& manhattan() {
  static const PoseGraph2 graph = [] {
    sim::ManhattanOptions o;
    o.poses = 1500;
    o.grid = 20;
    return sim::manhattanWorld(o).graph;
  }();
  return graph;
}

const PoseGraph3& gridGraph() {
  static const PoseGraph3 graph = [] {
    sim::GridOptions o;
    o.poses = 500;
    o.size = 5;
    return sim::gridWorld(o).graph;
  }();
  return graph;
}

template <class G>
std::string g2oText(const PoseGraph<G>& graph) {
  std::ostringstream os;
  writeG2o(os, graph, graph.poses);
  return os.str();
}

// The half-width of the false measurements' translation box, from the real loop closures.
template <class G>
double boxHalfWidth(const PoseGraph<G>& graph, int edges) {
  double largest = 0;
  for (int k = 0; k < edges; ++k) {
    const auto& e = graph.edges[k];
    if (std::abs(e.i - e.j) > 1) {
      largest = std::max(largest, e.measurement.translation().cwiseAbs().maxCoeff());
    }
  }
  return 3.0 * std::max(1.0, largest);
}

bool sameMeasurement(const SE2& a, const SE2& b) {
  return a.translation() == b.translation() && a.angle() == b.angle();
}
bool sameMeasurement(const SE3& a, const SE3& b) {
  return a.translation() == b.translation() && a.quaternion().coeffs() == b.quaternion().coeffs();
}

// What every policy promises: the input's edges first and unchanged, then round_half_even(f·L)
// false edges whose pairs are `pairs`, i < j, |i − j| > 1, on pairs no edge held before and
// none twice, each with a real loop closure's Ω and a measurement in the box.
template <class G>
void expectCommonProperties(const PoseGraph<G>& input, const sim::FalseClosures<G>& out,
                            double fraction) {
  const int m = input.numEdges();
  const int count = sim::falseClosureCount(fraction, sim::countLoopClosures(input));
  ASSERT_EQ(out.first_false, m);
  ASSERT_EQ(out.graph.numEdges(), m + count);
  ASSERT_EQ(static_cast<int>(out.pairs.size()), count);
  EXPECT_EQ(out.graph.poses.size(), input.poses.size());
  for (int k = 0; k < m; ++k) {
    ASSERT_EQ(out.graph.edges[k].i, input.edges[k].i);
    ASSERT_EQ(out.graph.edges[k].j, input.edges[k].j);
    ASSERT_TRUE(sameMeasurement(out.graph.edges[k].measurement, input.edges[k].measurement));
  }
  std::set<std::pair<int, int>> seen;
  for (const auto& e : input.edges) seen.insert({std::min(e.i, e.j), std::max(e.i, e.j)});
  std::vector<typename RelativePoseEdge<G>::Matrix> closure_information;
  for (const auto& e : input.edges) {
    if (std::abs(e.i - e.j) > 1) closure_information.push_back(e.information);
  }
  const double h = boxHalfWidth(input, m);
  for (int k = 0; k < count; ++k) {
    const auto& e = out.graph.edges[m + k];
    EXPECT_EQ(std::make_pair(e.i, e.j), out.pairs[k]) << k;
    EXPECT_LT(e.i, e.j) << k;
    EXPECT_GT(e.j - e.i, 1) << k;
    EXPECT_TRUE(seen.insert({e.i, e.j}).second) << "pair " << e.i << " " << e.j << " twice";
    EXPECT_TRUE(std::any_of(closure_information.begin(), closure_information.end(),
                            [&](const auto& omega) { return omega == e.information; }))
        << "false edge " << k << " has an Ω no real loop closure has";
    EXPECT_LE(e.measurement.translation().cwiseAbs().maxCoeff(), h) << k;
  }
}

TEST(FalseClosures, CountIsTheFractionOfLoopClosuresRoundedHalfToEven) {
  EXPECT_EQ(sim::falseClosureCount(0.0, 100), 0);
  EXPECT_EQ(sim::falseClosureCount(0.1, 1954), 195);  // 195.4
  EXPECT_EQ(sim::falseClosureCount(0.5, 1954), 977);  // exact
  EXPECT_EQ(sim::falseClosureCount(0.1, 785), 78);    // 78.5: half to even, down
  EXPECT_EQ(sim::falseClosureCount(0.9, 785), 706);   // 706.5: down
  EXPECT_EQ(sim::falseClosureCount(0.1, 4615), 462);  // 461.5: up
  EXPECT_EQ(sim::falseClosureCount(0.1, 6448), 645);  // 644.8
  EXPECT_EQ(sim::falseClosureCount(2.0, 30), 60);     // more false closures than real ones
  EXPECT_EQ(sim::countLoopClosures(manhattan()),
            std::count_if(manhattan().edges.begin(), manhattan().edges.end(),
                          [](const auto& e) { return e.j != e.i + 1; }));
}

TEST(FalseClosures, RandomPairsAreAnyPairsApartByMoreThanOne) {
  const OutlierOptions o{0.5, OutlierPolicy::kRandom, 7};
  const auto out = sim::addFalseClosures(manhattan(), o);
  expectCommonProperties(manhattan(), out, o.fraction);
  // Spread over the whole trajectory, not a window: some pairs are far apart.
  int far = 0;
  for (const auto& [i, j] : out.pairs) far += j - i > 500;
  EXPECT_GT(far, static_cast<int>(out.pairs.size()) / 4);
  // Each has its own measurement.
  std::set<double> x;
  for (int k = out.first_false; k < out.graph.numEdges(); ++k) {
    x.insert(out.graph.edges[k].measurement.x());
  }
  EXPECT_EQ(x.size(), out.pairs.size());
}

TEST(FalseClosures, LocalPairsAreTenToFiftyPosesApart) {
  const OutlierOptions o{0.3, OutlierPolicy::kLocal, 7};
  const auto out = sim::addFalseClosures(manhattan(), o);
  expectCommonProperties(manhattan(), out, o.fraction);
  std::set<int> gaps;
  for (const auto& [i, j] : out.pairs) {
    EXPECT_GE(j - i, 10);
    EXPECT_LE(j - i, 50);
    gaps.insert(j - i);
  }
  EXPECT_GT(gaps.size(), 30u);  // the window's gaps are all used, not one
  // A narrower window is honoured too.
  OutlierOptions narrow = o;
  narrow.local_min = narrow.local_max = 20;
  for (const auto& [i, j] : sim::addFalseClosures(manhattan(), narrow).pairs) EXPECT_EQ(j - i, 20);
}

// Groups of 10 consecutive pairs (i₀ + k, j₀ + k) with one measurement; the last group cut to
// the count; different groups, different measurements.
template <class G>
void expectGroups(const PoseGraph<G>& graph, double fraction) {
  const OutlierOptions o{fraction, OutlierPolicy::kGroup, 3};
  const auto out = sim::addFalseClosures(graph, o);
  expectCommonProperties(graph, out, fraction);
  const int count = static_cast<int>(out.pairs.size());
  ASSERT_GT(count, 20);
  ASSERT_NE(count % 10, 0) << "pick a fraction that leaves a short last group";
  std::vector<G> group_z;
  for (int start = 0; start < count; start += 10) {
    const auto& first = out.graph.edges[out.first_false + start];
    for (int k = 1; k < std::min(10, count - start); ++k) {
      const auto& e = out.graph.edges[out.first_false + start + k];
      EXPECT_EQ(e.i, first.i + k) << start << "+" << k;
      EXPECT_EQ(e.j, first.j + k) << start << "+" << k;
      EXPECT_TRUE(sameMeasurement(e.measurement, first.measurement)) << start << "+" << k;
    }
    for (const G& z : group_z) EXPECT_FALSE(sameMeasurement(z, first.measurement)) << start;
    group_z.push_back(first.measurement);
  }
  // The next group does not continue the previous run: it starts a new pair of runs.
  int continued = 0;
  for (int start = 10; start < count; start += 10) {
    const auto& [pi, pj] = out.pairs[start - 1];
    continued += out.pairs[start] == std::make_pair(pi + 1, pj + 1);
  }
  EXPECT_EQ(continued, 0);
}

TEST(FalseClosures, GroupsOfTenConsecutivePairsShareOneFalseTransform) {
  expectGroups(manhattan(), 0.1);
  expectGroups(gridGraph(), 0.3);
}

// A group claims one rigid offset z between its two runs: poses placed by xⱼ₀₊ₖ = xᵢ₀₊ₖ · z
// satisfy every edge of the group exactly, so the group agrees with itself.
TEST(FalseClosures, AGroupIsSatisfiedExactlyByOneRigidOffset) {
  const auto out = sim::addFalseClosures(manhattan(), {0.05, OutlierPolicy::kGroup, 11});
  ASSERT_GE(out.pairs.size(), 10u);
  std::vector<SE2> x = out.graph.poses;
  const SE2 z = out.graph.edges[out.first_false].measurement;
  for (int k = 0; k < 10; ++k) x[out.pairs[k].second] = x[out.pairs[k].first].compose(z);
  for (int k = 0; k < 10; ++k) {
    const auto& e = out.graph.edges[out.first_false + k];
    EXPECT_LT(e.cost(x[e.i], x[e.j]), 1e-18) << k;
  }
  // … while at the file's own estimate each of them is far off.
  const auto& e = out.graph.edges[out.first_false];
  EXPECT_GT(e.cost(out.graph.poses[e.i], out.graph.poses[e.j]), 1.0);
}

TEST(FalseClosures, ThreeDimensionalGraphsGetUnitQuaternionsWithNonNegativeW) {
  for (const auto policy : {OutlierPolicy::kRandom, OutlierPolicy::kLocal}) {
    const OutlierOptions o{0.5, policy, 5};
    const auto out = sim::addFalseClosures(gridGraph(), o);
    expectCommonProperties(gridGraph(), out, o.fraction);
    for (int k = out.first_false; k < out.graph.numEdges(); ++k) {
      const auto& q = out.graph.edges[k].measurement.quaternion();
      EXPECT_NEAR(q.norm(), 1.0, 1e-12);
      EXPECT_GE(q.w(), 0.0);
    }
  }
}

// Haar measure on SO(3): the rotation angle θ = 2 acos|w| has CDF (θ − sin θ)/π; on SO(2) θ is
// uniform. A quaternion normalised from a uniform box, for one, fails the first (its CDF at π/2
// is 0.21, not 0.18). Translations fill [−h, h] per axis.
TEST(FalseClosures, RandomRotationsAreUniform) {
  const int n = 40000;
  sim::Random rng(9);
  std::vector<double> angle3, angle2;
  double lo = 0, hi = 0;
  for (int k = 0; k < n; ++k) {
    const SE3 x = sim::randomPose<SE3>(rng, 2.0);
    angle3.push_back(2.0 * std::acos(std::min(1.0, std::abs(x.quaternion().w()))));
    lo = std::min(lo, x.translation().minCoeff());
    hi = std::max(hi, x.translation().maxCoeff());
    angle2.push_back(sim::randomPose<SE2>(rng, 2.0).angle());
  }
  EXPECT_GE(lo, -2.0);
  EXPECT_LE(hi, 2.0);
  EXPECT_LT(lo, -1.99);
  EXPECT_GT(hi, 1.99);
  for (const double t : {M_PI / 4, M_PI / 2, 3 * M_PI / 4}) {
    const double below3 =
        std::count_if(angle3.begin(), angle3.end(), [&](double a) { return a < t; }) /
        static_cast<double>(n);
    EXPECT_NEAR(below3, (t - std::sin(t)) / M_PI, 0.01) << "SO(3) at " << t;
    const double below2 =
        std::count_if(angle2.begin(), angle2.end(), [&](double a) { return a < t - M_PI; }) /
        static_cast<double>(n);
    EXPECT_NEAR(below2, t / (2 * M_PI), 0.01) << "SO(2) at " << t - M_PI;
  }
}

TEST(FalseClosures, SameSeedSameGraphOtherSeedOtherGraph) {
  for (const auto policy : {OutlierPolicy::kRandom, OutlierPolicy::kLocal, OutlierPolicy::kGroup}) {
    const OutlierOptions a{0.2, policy, 4};
    OutlierOptions b = a;
    b.seed = 5;
    const std::string first = g2oText(sim::addFalseClosures(manhattan(), a).graph);
    // (== rather than EXPECT_EQ on the texts: a failure would print the whole graph)
    EXPECT_TRUE(first == g2oText(sim::addFalseClosures(manhattan(), a).graph)) << toString(policy);
    EXPECT_TRUE(first != g2oText(sim::addFalseClosures(manhattan(), b).graph)) << toString(policy);
  }
}

// Written as g2o and read back, the graph holds the same edges, the false ones last; the labels
// (file ids) read back as written and name those last edges.
TEST(FalseClosures, WrittenGraphAndLabelsReadBack) {
  // Ids 100, 102, 104, …: the labels are file ids, not dense indices.
  PoseGraph2 input = manhattan();
  for (int k = 0; k < input.numPoses(); ++k) {
    input.ids[k] = 100 + 2 * k;
  }
  input.index.clear();
  for (int k = 0; k < input.numPoses(); ++k) input.index[input.ids[k]] = k;
  const auto out = sim::addFalseClosures(input, {0.1, OutlierPolicy::kGroup, 2});
  std::vector<LabelPair> labels;
  for (const auto& [i, j] : out.pairs) labels.emplace_back(input.ids[i], input.ids[j]);
  std::stringstream labels_text;
  writeLabels(labels_text, labels);
  EXPECT_EQ(readLabels(labels_text, "labels"), labels);

  std::stringstream g2o(g2oText(out.graph));
  const auto read = std::get<PoseGraph2>(readPoseGraph(g2o, "out.g2o"));
  ASSERT_EQ(read.numEdges(), out.graph.numEdges());
  ASSERT_EQ(read.numPoses(), out.graph.numPoses());
  for (int k = 0; k < read.numEdges(); ++k) {
    ASSERT_EQ(read.edges[k].i, out.graph.edges[k].i);
    ASSERT_EQ(read.edges[k].j, out.graph.edges[k].j);
    // The angle is written exactly; cos and sin are recomputed from it, to the last bit or so.
    ASSERT_EQ(read.edges[k].measurement.translation(),
              out.graph.edges[k].measurement.translation());
    ASSERT_NEAR(read.edges[k].measurement.angle(), out.graph.edges[k].measurement.angle(), 1e-15);
    ASSERT_EQ(read.edges[k].information, out.graph.edges[k].information) << k;
  }
  for (size_t k = 0; k < labels.size(); ++k) {
    const auto& e = read.edges[out.first_false + k];
    EXPECT_EQ(std::make_pair(read.ids[e.i], read.ids[e.j]), labels[k]);
  }
}

TEST(FalseClosures, MalformedLabelsNameTheLine) {
  const std::vector<std::pair<std::string, std::string>> cases = {
      {"1 2\n3\n", "f.labels:2: expected two pose ids"},
      {"1 2\n\n4 x\n", "f.labels:3: pose id 'x'"},
      {"1 2\n-3 4\n", "f.labels:2: pose id '-3' is a negative id"},
      {"1 2\n5 6 7\n", "f.labels:2: expected two pose ids 'i j', found 3 fields"},
  };
  for (const auto& [text, words] : cases) {
    std::istringstream in(text);
    try {
      readLabels(in, "f.labels");
      ADD_FAILURE() << text;
    } catch (const FileError& e) {
      EXPECT_NE(std::string(e.what()).find(words), std::string::npos) << e.what();
    }
  }
  std::istringstream comments("# false edges\n1 2  # first\n\n3 4\n");
  EXPECT_EQ(readLabels(comments, "c"), (std::vector<LabelPair>{{1, 2}, {3, 4}}));
}

void expectRefused(const PoseGraph2& graph, const OutlierOptions& o, const std::string& words) {
  try {
    sim::addFalseClosures(graph, o);
    ADD_FAILURE() << "accepted; expected: " << words;
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find(words), std::string::npos) << e.what();
  }
}

// Twelve poses on a line, odometry and the loop closures (0, 5), (2, 9), (3, 11): of the 66
// pose pairs 11 are neighbours and 3 are taken, 52 free.
PoseGraph2 twelvePoses() {
  PoseGraph2 g;
  for (int k = 0; k < 12; ++k) {
    g.ids.push_back(k);
    g.index[k] = k;
    g.poses.emplace_back(k, 0.0, 0.0);
  }
  auto edge = [&](int i, int j) {
    g.edges.push_back(RelativePoseEdge<SE2>::make(i, j, g.poses[i].between(g.poses[j]),
                                                  Eigen::Matrix3d::Identity()));
  };
  for (int k = 1; k < 12; ++k) edge(k - 1, k);
  edge(0, 5);
  edge(2, 9);
  edge(3, 11);
  g.has_initial_estimate = true;
  return g;
}

TEST(FalseClosures, BadOptionsAreRefusedNamingTheValue) {
  expectRefused(manhattan(), {-0.1, OutlierPolicy::kRandom, 1}, "-0.1");
  expectRefused(manhattan(), {std::nan(""), OutlierPolicy::kRandom, 1}, "finite");
  expectRefused(manhattan(), {INFINITY, OutlierPolicy::kRandom, 1}, "finite");
  expectRefused(manhattan(), {1e12, OutlierPolicy::kRandom, 1}, "too many");
  OutlierOptions o{0.1, OutlierPolicy::kGroup, 1};
  o.group_size = 0;
  expectRefused(manhattan(), o, "group size must be >= 1, not 0");
  o = {0.1, OutlierPolicy::kLocal, 1};
  o.local_min = 1;
  expectRefused(manhattan(), o, "[1, 50]");
  o.local_min = 60;
  expectRefused(manhattan(), o, "[60, 50]");

  const PoseGraph2 twelve = twelvePoses();
  ASSERT_EQ(sim::countLoopClosures(twelve), 3);
  // The 10–50 window holds three pairs in twelve poses: (0, 10), (1, 11), (0, 11).
  const auto local = sim::addFalseClosures(twelve, {1.0, OutlierPolicy::kLocal, 1});
  using PairSet = std::set<std::pair<int, int>>;
  const PairSet window = {{0, 10}, {1, 11}, {0, 11}};
  EXPECT_EQ(PairSet(local.pairs.begin(), local.pairs.end()), window);
  expectRefused(twelve, {2.0, OutlierPolicy::kLocal, 1}, "only 3 free pose pairs");
  o = {1.0, OutlierPolicy::kLocal, 1};
  o.local_min = o.local_max = 12;
  expectRefused(twelve, o, "the graph has 12 poses (needs at least 13)");
  expectRefused(twelve, {100.0, OutlierPolicy::kRandom, 1}, "only 52 free pose pairs");
  OutlierOptions group{4.0, OutlierPolicy::kGroup, 1};
  group.group_size = 11;
  expectRefused(twelve, group, "a group of 11 consecutive false closures needs at least 13 poses");

  PoseGraph2 one;
  one.ids = {0};
  one.index[0] = 0;
  one.poses = {SE2()};
  expectRefused(one, {0.1, OutlierPolicy::kRandom, 1}, "at least two poses, the graph has 1");
}

// Every free pair asked for: the draws still end, each pair once.
TEST(FalseClosures, EveryFreePairCanBeTaken) {
  const PoseGraph2 twelve = twelvePoses();
  const OutlierOptions o{52.0 / 3.0, OutlierPolicy::kRandom, 1};
  ASSERT_EQ(sim::falseClosureCount(o.fraction, 3), 52);
  const auto out = sim::addFalseClosures(twelve, o);
  expectCommonProperties(twelve, out, o.fraction);
}

// data/'s graphs with false closures are what `arbor generate … --outliers` makes (the commands
// are in data/README.md): the clean file's bytes, then the false edges; the labels name them.
TEST(FalseClosures, CommittedRobustDataMatchesGenerator) {
  const std::string dir = std::string(ARBOR_SOURCE_DIR) + "/data/";
  auto fileText = [](const std::string& path) {
    std::ifstream in(path);
    std::stringstream s;
    s << in.rdbuf();
    return s.str();
  };
  auto expectFiles = [&](const auto& graph, const OutlierOptions& o, const std::string& clean,
                         const std::string& name) {
    SCOPED_TRACE(name);
    const auto out = sim::addFalseClosures(graph, o);
    std::vector<LabelPair> labels;
    for (const auto& [i, j] : out.pairs) labels.emplace_back(graph.ids[i], graph.ids[j]);
    std::ostringstream labels_text;
    writeLabels(labels_text, labels);
    const std::string text = fileText(dir + name + ".g2o");
    EXPECT_TRUE(text == g2oText(out.graph)) << "regenerate " << name << " (data/README.md)";
    EXPECT_EQ(text.rfind(fileText(dir + clean + ".g2o"), 0), 0u) << "starts with " << clean;
    EXPECT_EQ(fileText(dir + name + ".labels"), labels_text.str());
  };
  sim::ManhattanOptions m;
  m.poses = 1500;
  m.grid = 20;
  m.seed = 1;
  expectFiles(sim::manhattanWorld(m).graph, {0.1, OutlierPolicy::kGroup, 1}, "manhattan_2d",
              "manhattan_2d_group_0.1");
  sim::SphereOptions sp;
  sp.rings = 10;
  sp.poses_per_ring = 25;
  sp.seed = 1;
  expectFiles(sim::sphereWorld(sp).graph, {0.1, OutlierPolicy::kRandom, 1}, "sphere_3d",
              "sphere_3d_random_0.1");
}

// The shared robust files were made by the same rules: their counts are round_half_even(f · L)
// of their base file, their labels are the appended edges, pairs are |i − j| > 1 (local:
// 10–50), every false Ω is a real loop closure's, every false translation lies in the box.
TEST(FalseClosures, SharedRobustFilesFollowTheSameRules) {
  const std::filesystem::path dir = testing::sharedDir() + "/datasets/robust";
  if (!std::filesystem::exists(dir)) GTEST_SKIP() << dir << " absent";
  int files = 0;
  for (const auto& entry : std::filesystem::directory_iterator(dir)) {
    if (entry.path().extension() != ".g2o") continue;
    const std::string name = entry.path().stem().string();  // BASE_POLICY_FRACTION
    const size_t b = name.rfind('_'), a = name.rfind('_', b - 1);
    const std::string base = name.substr(0, a), policy = name.substr(a + 1, b - a - 1);
    const double fraction = std::stod(name.substr(b + 1));
    SCOPED_TRACE(name);
    const auto labels = readLabelsFile((dir / (name + ".labels")).string());
    std::visit(
        [&](const auto& robust) {
          using G = typename std::decay_t<decltype(robust)>::GroupType;
          const auto clean = std::get<PoseGraph<G>>(readPoseGraphFile(testing::datasetPath(base)));
          const int m = clean.numEdges();
          EXPECT_EQ(static_cast<int>(labels.size()),
                    sim::falseClosureCount(fraction, sim::countLoopClosures(clean)));
          ASSERT_EQ(robust.numEdges(), m + static_cast<int>(labels.size()));
          std::vector<typename RelativePoseEdge<G>::Matrix> omegas;
          for (const auto& e : clean.edges) {
            if (std::abs(e.i - e.j) > 1) omegas.push_back(e.information);
          }
          const double h = boxHalfWidth(clean, m);
          for (size_t k = 0; k < labels.size(); ++k) {
            const auto& e = robust.edges[m + k];
            EXPECT_EQ(std::make_pair(robust.ids[e.i], robust.ids[e.j]), labels[k]);
            EXPECT_GT(e.j - e.i, 1);
            if (policy == "local") {
              EXPECT_GE(e.j - e.i, 10);
              EXPECT_LE(e.j - e.i, 50);
            }
            EXPECT_LE(e.measurement.translation().cwiseAbs().maxCoeff(), h);
            EXPECT_TRUE(std::any_of(omegas.begin(), omegas.end(), [&](const auto& omega) {
              return (omega - e.information).norm() <= 1e-9 * omega.norm();
            }));
          }
        },
        readPoseGraphFile(entry.path().string()));
    ++files;
  }
  EXPECT_GT(files, 0);
}

}  // namespace
}  // namespace arbor
