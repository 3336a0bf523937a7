// Random corruption of the project's own g2o files (fixed seeds): every corrupted file is either
// refused with a FileError naming its line, or read and replayed to a finite estimate. Never
// another exception, a crash or NaN. (A fuzzer of this kind found that an edge of −1e308 m,
// finite and so once accepted, made a whole replay's estimate NaN; docs/design.md.)
#include <cmath>
#include <fstream>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "io/pose_graph_file.h"
#include "tools/cli/cli_common.h"
#include "tools/cli/replay_runner.h"

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

void fuzz(const std::string& file, unsigned seed, int rounds) {
  cli::useOneBlasThread();  // as the tools do: the smoother's own threads share the cores
  const std::vector<std::string> lines = readLines(std::string(ARBOR_SOURCE_DIR) + "/data/" + file);
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

// Seeds and rounds chosen so that each test meets at least one of the overflowing values
// (checked by disabling kMaxTranslation and kMaxInformationEntry: each then fails).
TEST(InputFuzz, CorruptedGridIsRefusedOrReplayedToAFiniteEstimate) { fuzz("grid_3d.g2o", 1, 40); }

TEST(InputFuzz, CorruptedSphereIsRefusedOrReplayedToAFiniteEstimate) {
  fuzz("sphere_3d.g2o", 2, 40);
}

TEST(InputFuzz, CorruptedManhattanIsRefusedOrReplayedToAFiniteEstimate) {
  fuzz("manhattan_2d.g2o", 9, 150);
}

}  // namespace
}  // namespace arbor
