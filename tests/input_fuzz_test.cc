// Random corruption of the project's own g2o files and of small generated graphs with priors
// (fixed seeds): every corrupted file is either refused with a FileError naming its line, or
// read and replayed to a finite estimate. Never another exception, a crash or NaN. (A fuzzer of
// this kind found that an edge of −1e308 m, finite and so once accepted, made a whole replay's
// estimate NaN; docs/design.md.)
#include <cmath>
#include <fstream>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "arbor_slam/io/pose_graph_file.h"
#include "arbor_slam/tests/random_graphs.h"
#include "arbor_slam/tools/cli/cli_common.h"
#include "arbor_slam/tools/cli/replay_runner.h"

namespace arbor {
namespace {

std::vector<std::string> readLines(const std::string& path) {
  std::ifstream in(path);
  std::vector<std::string> lines;
  for (std::string line; std::getline(in, line);) lines.push_back(line);
  return lines;
}

std::vector<std::string> tokens(const std::string& line) {
  std::istringstream in(line);
  std::vector<std::string> out;
  for (std::string t; in >> t;) out.push_back(t);
  return out;
}

// One to four mutations: a token replaced by a hostile value, a token dropped, a digit
// appended, an id changed, a line duplicated, two lines swapped.
std::string corrupt(std::vector<std::string> lines, std::mt19937& rng) {
  static const char* const kHostile[] = {
      "nan",       "inf",  "-inf",  "1e308",  "-1e308", "0",          "-1",
      "999999999", "abc",  "1e400", "1e-320", "3.4.5",  "0x10",       "#",
      "FIX",       "1e31", "-2e15", "",       "EDGE2",  "VERTEX_SE2", "9223372036854775807"};
  const int mutations = 1 + static_cast<int>(rng() % 4);
  for (int m = 0; m < mutations; ++m) {
    const size_t at = rng() % lines.size();
    std::vector<std::string> t = tokens(lines[at]);
    switch (rng() % 6) {
      case 0:
        if (!t.empty()) t[rng() % t.size()] = kHostile[rng() % std::size(kHostile)];
        break;
      case 1:
        if (!t.empty()) t.erase(t.begin() + static_cast<long>(rng() % t.size()));
        break;
      case 2:
        if (!t.empty()) t[rng() % t.size()] += std::to_string(rng() % 10);
        break;
      case 3:
        if (t.size() > 2) t[1 + rng() % 2] = std::to_string(static_cast<int>(rng() % 40) - 5);
        break;
      case 4:
        lines.push_back(lines[at]);
        continue;
      default:
        std::swap(lines[at], lines[rng() % lines.size()]);
        continue;
    }
    std::string joined;
    for (const std::string& token : t) joined += token + " ";
    lines[at] = joined;
  }
  std::string text;
  for (const std::string& line : lines) text += line + "\n";
  return text;
}

void fuzzLines(const std::string& file, const std::vector<std::string>& lines, unsigned seed,
               int rounds) {
  ASSERT_FALSE(lines.empty()) << file;
  std::mt19937 rng(seed);
  int read = 0, refused = 0;
  for (int round = 0; round < rounds; ++round) {
    const std::string text = corrupt(lines, rng);
    std::istringstream in(text);
    AnyPoseGraph graph;
    try {
      ReadOptions options;
      options.information = InformationPolicy::kRepair;
      graph = readPoseGraph(in, "fuzz.g2o", options);
    } catch (const FileError& e) {
      ++refused;
      EXPECT_EQ(std::string(e.what()).rfind("fuzz.g2o", 0), 0u) << e.what();
      continue;
    }
    ++read;
    std::visit(
        [&](const auto& g) {
          cli::ReplaySettings settings;
          settings.batch = round % 4 == 0;
          const auto r = cli::runReplay(g, settings);
          EXPECT_TRUE(std::isfinite(r.F_final)) << file << " seed " << seed << " round " << round;
          if (settings.batch) {
            EXPECT_TRUE(std::isfinite(r.batch.F_final)) << file << " round " << round;
          }
        },
        graph);
  }
  EXPECT_GT(read, 0);
  EXPECT_GT(refused, 0);
}

void fuzz(const std::string& file, unsigned seed, int rounds) {
  fuzzLines(file, readLines(std::string(ARBOR_SOURCE_DIR) + "/data/" + file), seed, rounds);
}

// The lines writeG2o gives for a small graph with priors: a 30-pose chain with loop closures
// every 10 poses, two pose priors (in 3D with a sensor offset, so PARAMS_SE3OFFSET lines too)
// and three position priors.
template <class G>
std::vector<std::string> linesWithPriors(unsigned seed) {
  std::mt19937_64 rng(seed);
  constexpr int kPoses = 30;
  PoseGraph<G> graph;
  std::vector<G> truth = {G::Identity()};
  typename G::Tangent forward = G::Tangent::Zero();
  forward(0) = 1.0;
  for (int k = 1; k < kPoses; ++k) {
    truth.push_back(
        truth.back().compose(G::Exp(forward + testing::randomTangent<G>(rng, 0.1, 0.2))));
  }
  for (int k = 0; k < kPoses; ++k) {
    graph.ids.push_back(k);
    graph.index[k] = k;
    graph.poses.push_back(truth[k].compose(G::Exp(testing::randomTangent<G>(rng, 0.05, 0.02))));
  }
  const auto addEdge = [&](int i, int j) {
    const G z =
        truth[i].between(truth[j]).compose(G::Exp(testing::randomTangent<G>(rng, 0.02, 0.01)));
    graph.edges.push_back(RelativePoseEdge<G>::make(i, j, z, testing::randomInformation<G>(rng)));
  };
  for (int k = 0; k + 1 < kPoses; ++k) addEdge(k, k + 1);
  for (int k = 10; k < kPoses; k += 10) addEdge(k - 10, k);
  const G offset = G::Exp(testing::randomTangent<G>(rng, 0.3, 0.1));
  for (int k : {0, 20}) {
    graph.pose_priors.push_back(PosePriorFactor<G>::make(
        k, truth[k].compose(G::kDim == 3 ? offset : G::Identity()),
        testing::randomInformation<G>(rng), G::kDim == 3 ? offset : G::Identity()));
  }
  for (int k : {5, 15, 25}) {
    graph.position_priors.push_back(PositionPriorFactor<G>::make(
        k, truth[k].translation(), 4.0 * PositionPriorFactor<G>::Matrix::Identity()));
  }
  graph.has_initial_estimate = true;
  std::ostringstream out;
  writeG2o(out, graph, graph.poses);
  std::vector<std::string> lines;
  std::istringstream in(out.str());
  for (std::string line; std::getline(in, line);) lines.push_back(line);
  return lines;
}

// Seeds and rounds chosen so that each test meets at least one of the overflowing values
// (checked by disabling kMaxTranslation and kMaxInformationEntry: each then fails).
TEST(InputFuzz, CorruptedGridIsRefusedOrReplayedToAFiniteEstimate) { fuzz("grid_3d.g2o", 1, 40); }

TEST(InputFuzz, CorruptedSphereIsRefusedOrReplayedToAFiniteEstimate) {
  fuzz("sphere_3d.g2o", 2, 40);
}

TEST(InputFuzz, CorruptedManhattanIsRefusedOrReplayedToAFiniteEstimate) {
  fuzz("manhattan_2d.g2o", 9, 150);
}

TEST(InputFuzz, CorruptedPriors2DAreRefusedOrReplayedToAFiniteEstimate) {
  fuzzLines("priors_2d", linesWithPriors<SE2>(3), 5, 300);
}

TEST(InputFuzz, CorruptedPriors3DAreRefusedOrReplayedToAFiniteEstimate) {
  fuzzLines("priors_3d", linesWithPriors<SE3>(4), 6, 300);
}

}  // namespace
}  // namespace arbor
