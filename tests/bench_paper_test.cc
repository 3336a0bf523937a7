// The runner behind `arbor bench paper` (tools/bench/paper_runner.h) on small generated graphs:
// every solver runs and scores a finite F, the local solvers and RTR agree on an easy graph, an
// external solver is called from the spanning-tree start, and the files are written.
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "arbor_slam/core/initialization.h"
#include "arbor_slam/tools/bench/paper_runner.h"
#include "arbor_slam/tools/generator/graph_generator.h"

namespace arbor {
namespace {

namespace fs = std::filesystem;

fs::path scratchDir(const std::string& name) {
  const fs::path dir = fs::temp_directory_path() /
                       ("arbor_bench_paper_test_" + name + "_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  fs::create_directories(dir);
  return dir;
}

int countLines(const fs::path& path) {
  std::ifstream in(path);
  int n = 0;
  for (std::string line; std::getline(in, line);) ++n;
  return n;
}

const bench::SolverRun& run(const bench::DatasetReport& report, const std::string& solver) {
  for (const auto& r : report.runs) {
    if (r.solver == solver) return r;
  }
  throw std::runtime_error("no run of " + solver);
}

template <class G>
void expectAgreement(const bench::DatasetReport& report, int poses) {
  const std::vector<std::string> expected = {"replay", "lm", "gn", "dogleg", "rtr", "fake"};
  ASSERT_EQ(report.runs.size(), expected.size());
  for (size_t k = 0; k < expected.size(); ++k) {
    const auto& r = report.runs[k];
    EXPECT_EQ(r.solver, expected[k]);
    EXPECT_TRUE(std::isfinite(r.F)) << r.solver << ": " << r.note;
    EXPECT_NE(r.termination, "failed") << r.solver << ": " << r.note;
    ASSERT_FALSE(r.estimate_file.empty()) << r.solver;
    EXPECT_EQ(countLines(r.estimate_file), poses + 1) << r.estimate_file;  // + header
  }
  // LM, GN, dogleg and RTR reach the same minimum of an easy graph.
  const double F_lm = run(report, "lm").F;
  for (const char* s : {"gn", "dogleg", "rtr"}) {
    EXPECT_NEAR(run(report, s).F, F_lm, 1e-6 * F_lm) << s;
  }
  EXPECT_EQ(run(report, "rtr").termination, "certified");
  EXPECT_EQ(run(report, "replay").termination, "complete");
  EXPECT_GT(run(report, "replay").iterations, 0);
  EXPECT_LT(run(report, "replay").F, 1.01 * F_lm);
  EXPECT_FALSE(report.latency_file.empty());
  EXPECT_GT(report.latency.max, 0);
}

// An external solver that leaves the start as it is: the runner must score the start.
template <class G>
bench::SolverRun keepStart(const PoseGraph<G>&, std::vector<G>*) {
  bench::SolverRun r;
  r.termination = "converged";
  r.iterations = 0;
  return r;
}

bench::ExternalSolver fakeSolver() { return {"fake", keepStart<SE2>, keepStart<SE3>}; }

// The paper runner on `graph` with the fake external solver, tight tolerances, output in `dir`.
template <class G>
bench::DatasetReport runPaper(const std::string& name, const PoseGraph<G>& graph,
                              const fs::path& dir) {
  bench::PaperSettings settings;
  settings.relative_tolerance = 1e-10;
  settings.out_dir = dir.string();
  return bench::runPaperBenchmark(name, graph, settings, {fakeSolver()});
}

TEST(BenchPaper, EverySolverOnSmallManhattanAgrees) {
  sim::ManhattanOptions options;
  options.poses = 150;
  options.grid = 5;
  options.seed = 3;
  const auto sim = sim::manhattanWorld(options);
  const fs::path dir = scratchDir("2d");
  const auto report = runPaper("manhattan150", sim.graph, dir);
  EXPECT_EQ(report.dim, 2);
  EXPECT_EQ(report.poses, 150);
  expectAgreement<SE2>(report, 150);
  // The external solver got the spanning-tree start and is scored at it.
  EXPECT_NEAR(run(report, "fake").F, objective(sim.graph, spanningTreeInitialization(sim.graph)),
              1e-9 * run(report, "fake").F);
  EXPECT_TRUE(fs::exists(dir / "estimates" / "manhattan150" / "lm.csv"));
  EXPECT_TRUE(fs::exists(dir / "latency" / "manhattan150.csv"));

  std::vector<bench::DatasetReport> reports = {report};
  reports[0].F_star = run(report, "lm").F;
  bench::writeResultsTsv((dir / "results.tsv").string(), reports);
  bench::writeResultsJson((dir / "results.json").string(), reports);
  EXPECT_EQ(countLines(dir / "results.tsv"), 1 + 6);
  std::ifstream json_in(dir / "results.json");
  const auto json = nlohmann::json::parse(json_in);
  ASSERT_EQ(json.size(), 1u);
  EXPECT_EQ(json[0]["runs"].size(), 6u);
  const std::string md = bench::paperMarkdown(reports, "fake");
  EXPECT_NE(md.find("| manhattan150 |"), std::string::npos);
  EXPECT_NE(md.find("Time ratio to fake"), std::string::npos);
  EXPECT_NE(md.find("per-update latency"), std::string::npos);
  // Every table row has as many cells as its header row.
  std::istringstream lines(md);
  size_t columns = 0;
  for (std::string line; std::getline(lines, line);) {
    if (line.empty() || line[0] != '|') {
      columns = 0;
      continue;
    }
    const size_t cells = std::count(line.begin(), line.end(), '|');
    if (columns == 0) columns = cells;
    EXPECT_EQ(cells, columns) << line;
  }
  fs::remove_all(dir);
}

TEST(BenchPaper, EverySolverOnSmallSphereAgrees) {
  sim::SphereOptions options;
  options.rings = 5;
  options.poses_per_ring = 12;
  options.seed = 2;
  const auto sim = sim::sphereWorld(options);
  const fs::path dir = scratchDir("3d");
  const auto report = runPaper("sphere60", sim.graph, dir);
  EXPECT_EQ(report.dim, 3);
  expectAgreement<SE3>(report, 60);
  std::ifstream csv(run(report, "rtr").estimate_file);
  std::string header;
  std::getline(csv, header);
  EXPECT_EQ(header, "x,y,z");
  fs::remove_all(dir);
}

TEST(BenchPaper, FailingSolverIsReportedAndOthersStillRun) {
  sim::ManhattanOptions options;
  options.poses = 40;
  options.grid = 4;
  const auto sim = sim::manhattanWorld(options);
  bench::ExternalSolver broken{"broken",
                               [](const PoseGraph2&, std::vector<SE2>*) -> bench::SolverRun {
                                 throw std::runtime_error("broken on purpose");
                               },
                               nullptr};
  bench::PaperSettings settings;
  settings.replay = false;
  const auto report = bench::runPaperBenchmark("small", sim.graph, settings, {broken});
  ASSERT_EQ(report.runs.size(), 5u);
  EXPECT_EQ(report.runs.back().solver, "broken");
  EXPECT_EQ(report.runs.back().termination, "failed");
  EXPECT_NE(report.runs.back().note.find("broken on purpose"), std::string::npos);
  EXPECT_FALSE(std::isfinite(report.runs.back().F));
  EXPECT_TRUE(report.runs.back().estimate_file.empty());
  EXPECT_TRUE(std::isfinite(run(report, "lm").F));
  const std::string md = bench::paperMarkdown({report});
  EXPECT_NE(md.find("broken on purpose"), std::string::npos);
  EXPECT_EQ(md.find("Time ratio"), std::string::npos);  // no ceres column: no ratio table
}

}  // namespace
}  // namespace arbor
