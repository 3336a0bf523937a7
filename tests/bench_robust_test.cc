// `arbor bench robust`'s judgement of an estimate (tools/bench/robust_metrics.h,
// robust_bench.h) on small generated graphs: precision and recall against labels with unordered
// pairs, the ATE after a rigid alignment, F over the base file's edges taken by id, and the
// wiring of a row (shared-file discovery, generation, the replay extension point). No timing.
#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <random>
#include <stdexcept>

#include "arbor_slam/io/pose_graph_file.h"
#include "arbor_slam/tools/bench/robust_bench.h"
#include "arbor_slam/tools/bench/robust_metrics.h"
#include "arbor_slam/tools/bench/robust_replay_hooks.h"
#include "arbor_slam/tools/cli/online_threshold.h"
#include "arbor_slam/tools/generator/false_closures.h"
#include "arbor_slam/tools/generator/graph_generator.h"

namespace arbor {
namespace {

namespace fs = std::filesystem;

PoseGraph2 smallManhattan() {
  sim::ManhattanOptions o;
  o.poses = 120;
  o.grid = 4;
  o.seed = 7;
  return sim::manhattanWorld(o).graph;
}

// A fresh directory under the test's temporary directory.
fs::path scratch(const std::string& name) {
  const fs::path dir = fs::temp_directory_path() /
                       ("arbor-bench-robust-test-" + name + "-" + std::to_string(::getpid()));
  fs::remove_all(dir);
  fs::create_directories(dir);
  return dir;
}

TEST(RobustMetrics, PrecisionAndRecallTakePairsUnordered) {
  const std::vector<LabelPair> labels = {{3, 7}, {10, 2}};
  // Both labels rejected, written the other way round, and one true edge rejected.
  bench::RejectionScore s = bench::scoreRejections({{7, 3}, {2, 10}, {4, 5}}, labels);
  EXPECT_EQ(s.rejected, 3);
  EXPECT_EQ(s.labels, 2);
  EXPECT_EQ(s.true_positives, 2);
  EXPECT_EQ(s.labels_found, 2);
  EXPECT_DOUBLE_EQ(s.precision, 2.0 / 3.0);
  EXPECT_DOUBLE_EQ(s.recall, 1.0);

  // Two rejected edges on one labelled pair: both are true positives, one label is found.
  s = bench::scoreRejections({{3, 7}, {7, 3}}, labels);
  EXPECT_DOUBLE_EQ(s.precision, 1.0);
  EXPECT_DOUBLE_EQ(s.recall, 0.5);

  // Nothing rejected: no precision; no labels: no recall.
  s = bench::scoreRejections({}, labels);
  EXPECT_TRUE(std::isnan(s.precision));
  EXPECT_DOUBLE_EQ(s.recall, 0.0);
  s = bench::scoreRejections({{1, 4}}, {});
  EXPECT_DOUBLE_EQ(s.precision, 0.0);
  EXPECT_TRUE(std::isnan(s.recall));
}

TEST(RobustMetrics, RejectedPairsAreFileIds) {
  PoseGraph2 g = smallManhattan();
  std::vector<char> rejected(g.edges.size(), 0);
  rejected[g.edges.size() - 1] = 1;
  const auto pairs = bench::rejectedPairs(g, rejected);
  ASSERT_EQ(pairs.size(), 1u);
  EXPECT_EQ(pairs[0].first, g.ids[g.edges.back().i]);
  EXPECT_EQ(pairs[0].second, g.ids[g.edges.back().j]);
  EXPECT_THROW(bench::rejectedPairs(g, std::vector<char>(3, 0)), std::invalid_argument);
}

template <class G>
std::vector<G> movedBy(const G& T, const std::vector<G>& poses) {
  std::vector<G> out;
  for (const G& x : poses) out.push_back(T.compose(x));
  return out;
}

TEST(RobustMetrics, AteIgnoresARigidMoveOfTheEstimate) {
  std::mt19937 rng(3);
  std::normal_distribution<double> n(0, 5);
  std::vector<SE2> ref2;
  std::vector<SE3> ref3;
  for (int k = 0; k < 30; ++k) {
    ref2.push_back(SE2::Exp(Eigen::Vector3d(n(rng), n(rng), n(rng))));
    Eigen::Matrix<double, 6, 1> tau;
    for (int d = 0; d < 6; ++d) tau(d) = n(rng);
    ref3.push_back(SE3::Exp(tau));
  }
  const SE2 T2 = SE2::Exp(Eigen::Vector3d(12, -4, 2.5));
  Eigen::Matrix<double, 6, 1> tau;
  tau << 3, -7, 1, 0.4, -1.1, 2.0;
  const SE3 T3 = SE3::Exp(tau);
  EXPECT_NEAR(bench::alignedAte(movedBy(T2, ref2), ref2), 0.0, 1e-9);
  EXPECT_NEAR(bench::alignedAte(movedBy(T3, ref3), ref3), 0.0, 1e-9);
  // Unaligned, the same estimate is far off.
  double unaligned = 0;
  for (size_t k = 0; k < ref2.size(); ++k)
    unaligned += (T2.compose(ref2[k]).translation() - ref2[k].translation()).squaredNorm();
  EXPECT_GT(std::sqrt(unaligned / ref2.size()), 1.0);
  EXPECT_THROW(bench::alignedAte(ref2, std::vector<SE2>(3)), std::invalid_argument);
}

TEST(RobustMetrics, AteOfASymmetricDeformationIsItsSize) {
  // Four poses on the x axis, moved ±d along it symmetrically about their centroid: no rigid
  // move brings them closer (the best fit is the identity), so the ATE is d.
  const double d = 0.25;
  const std::vector<double> x = {0, 1, 2, 3}, e = {d, -d, -d, d};
  std::vector<SE2> ref, est;
  for (size_t k = 0; k < x.size(); ++k) {
    ref.emplace_back(Eigen::Vector2d(x[k], 0), 0.0);
    est.emplace_back(Eigen::Vector2d(x[k] + e[k], 0), 0.3);
  }
  EXPECT_NEAR(bench::alignedAte(est, ref), d, 1e-12);
  // And after any rigid move of the estimate.
  EXPECT_NEAR(bench::alignedAte(movedBy(SE2::Exp(Eigen::Vector3d(5, 2, -1)), est), ref), d, 1e-9);
}

TEST(RobustMetrics, PosesAreTakenById) {
  PoseGraph2 from, onto;
  from.ids = {1, 2, 3, 5};
  onto.ids = {2, 5};
  for (int k = 0; k < 4; ++k) from.index[from.ids[k]] = k;
  for (int k = 0; k < 2; ++k) onto.index[onto.ids[k]] = k;
  std::vector<SE2> estimate;
  for (int k = 0; k < 4; ++k) estimate.emplace_back(Eigen::Vector2d(k, 10 * k), 0.1 * k);
  const auto picked = bench::posesByIds(from, estimate, onto);
  ASSERT_EQ(picked.size(), 2u);
  EXPECT_EQ(picked[0].x(), 1);
  EXPECT_EQ(picked[1].x(), 3);
  onto.ids.push_back(4);
  try {
    bench::posesByIds(from, estimate, onto);
    FAIL() << "a missing id was accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("pose 4"), std::string::npos) << e.what();
  }
}

TEST(RobustMetrics, FIsOverTheBaseEdgesOnly) {
  const PoseGraph2 base = smallManhattan();
  sim::OutlierOptions o;
  o.fraction = 0.3;
  const auto planted = sim::addFalseClosures(base, o);
  ASSERT_GT(planted.pairs.size(), 0u);
  const std::vector<SE2>& x = planted.graph.poses;
  const double clean = bench::cleanObjective(base, planted.graph, x);
  EXPECT_DOUBLE_EQ(clean, objective(base, base.poses));
  double over_base_edges = 0;
  for (int k = 0; k < planted.first_false; ++k)
    over_base_edges +=
        planted.graph.edges[k].cost(x[planted.graph.edges[k].i], x[planted.graph.edges[k].j]);
  EXPECT_DOUBLE_EQ(clean, over_base_edges);
  EXPECT_GT(objective(planted.graph, x), clean);  // the false edges cost, and are left out
}

// The labels of a FalseClosures result, as the generator writes them.
template <class G>
std::vector<LabelPair> labelsOf(const sim::FalseClosures<G>& planted) {
  std::vector<LabelPair> labels;
  for (const auto& [i, j] : planted.pairs)
    labels.emplace_back(planted.graph.ids[i], planted.graph.ids[j]);
  return labels;
}

TEST(RobustMetrics, JudgesAnEstimateAgainstTheCleanOptimum) {
  const PoseGraph2 base = smallManhattan();
  sim::OutlierOptions o;
  o.fraction = 0.2;
  o.policy = sim::OutlierPolicy::kGroup;
  const auto planted = sim::addFalseClosures(base, o);
  const std::vector<LabelPair> labels = labelsOf(planted);
  bench::CleanReference<SE2> ref = bench::cleanReference(base, std::nan(""));
  ASSERT_LT(ref.F, objective(base, base.poses));
  ref.F_star = ref.F;

  // The clean optimum moved rigidly, the false edges and nothing else rejected.
  bench::RobustEstimate<SE2> oracle;
  oracle.poses = movedBy(SE2::Exp(Eigen::Vector3d(3, -2, 0.7)), ref.optimum);
  oracle.rejected.assign(planted.graph.edges.size(), 0);
  for (size_t k = planted.first_false; k < oracle.rejected.size(); ++k) oracle.rejected[k] = 1;
  bench::RobustFigures f = bench::judgeEstimate(planted.graph, oracle, labels, ref);
  ASSERT_TRUE(f.ok) << f.error;
  EXPECT_NEAR(f.F_ratio, 1.0, 1e-9);
  EXPECT_NEAR(f.ate, 0.0, 1e-9);
  EXPECT_DOUBLE_EQ(f.score.precision, 1.0);
  EXPECT_DOUBLE_EQ(f.score.recall, 1.0);

  // One false edge kept, one loop closure of the base rejected in its place.
  const int n = static_cast<int>(labels.size());
  oracle.rejected[planted.first_false] = 0;
  int true_closure = -1;
  for (int k = 0; k < planted.first_false; ++k) {
    if (std::abs(base.edges[k].i - base.edges[k].j) > 1) true_closure = k;
  }
  ASSERT_GE(true_closure, 0);
  oracle.rejected[true_closure] = 1;
  f = bench::judgeEstimate(planted.graph, oracle, labels, ref);
  EXPECT_DOUBLE_EQ(f.score.precision, (n - 1.0) / n);
  EXPECT_DOUBLE_EQ(f.score.recall, (n - 1.0) / n);

  // The raw start instead of the optimum: F above F*, ATE above 0.
  oracle.poses = planted.graph.poses;
  f = bench::judgeEstimate(planted.graph, oracle, labels, ref);
  EXPECT_GT(f.F_ratio, 1.0);
  EXPECT_GT(f.ate, 0.0);

  // An estimate of the wrong size is a failed figure, not a throw.
  oracle.poses.pop_back();
  f = bench::judgeEstimate(planted.graph, oracle, labels, ref);
  EXPECT_FALSE(f.ok);
  EXPECT_FALSE(f.error.empty());
}

// A scratch shared folder holding datasets/tiny.g2o (smallManhattan) and its copy with
// planted group closures, datasets/robust/tiny_group_0.5.g2o with its labels; returns the
// planted graph.
sim::FalseClosures<SE2> writeSharedRobustFile(const fs::path& shared) {
  fs::create_directories(shared / "datasets" / "robust");
  const PoseGraph2 base = smallManhattan();
  writeG2oFile((shared / "datasets" / "tiny.g2o").string(), base, base.poses);
  auto planted = sim::addFalseClosures(base, sim::OutlierOptions{});
  writeG2oFile((shared / "datasets" / "robust" / "tiny_group_0.5.g2o").string(), planted.graph,
               planted.graph.poses);
  writeLabelsFile((shared / "datasets" / "robust" / "tiny_group_0.5.labels").string(),
                  labelsOf(planted));
  return planted;
}

TEST(RobustBench, FindsSharedFilesWithLabelsAndTheirBase) {
  const fs::path shared = scratch("shared");
  const auto planted = writeSharedRobustFile(shared);
  // Without labels: left out.
  writeG2oFile((shared / "datasets" / "robust" / "tiny_random_0.1.g2o").string(), planted.graph,
               planted.graph.poses);
  const auto cases = bench::sharedRobustCases(shared.string());
  ASSERT_EQ(cases.size(), 1u);
  EXPECT_EQ(cases[0].name, "tiny_group_0.5");
  EXPECT_EQ(cases[0].base, "tiny");
  EXPECT_EQ(cases[0].policy, "group");
  EXPECT_DOUBLE_EQ(cases[0].fraction, 0.5);
  EXPECT_EQ(fs::path(cases[0].base_file), shared / "datasets" / "tiny.g2o");
  EXPECT_FALSE(cases[0].generated);
  EXPECT_TRUE(bench::sharedRobustCases((shared / "absent").string()).empty());
  fs::remove_all(shared);
}

// The reference tools of robust-anchors.tsv (GTSAM GNC, riSAM, iSAM2 with a Cauchy kernel) reach
// a shared file's row by (dataset, tool), each in its own column; a tool with no row for the
// files benchmarked is said so under the table (the shared table has no isam2_cauchy rows).
TEST(RobustBench, AnchorsFillTheirColumnsAndAnAbsentToolIsSaid) {
  const fs::path shared = scratch("anchors");
  writeSharedRobustFile(shared);
  fs::create_directories(shared / "reference");
  {
    std::ofstream tsv(shared / "reference" / "robust-anchors.tsv");
    tsv << "# a comment\n"
           "dataset\ttool\ttotal_s\tp50_ms\tp99_ms\tmax_ms\trejected\tstatus\tF_clean\t"
           "F_clean/F*\tate\tprecision\trecall\n"
           "tiny_group_0.5\tgnc\t1.5\t0\t0\t0\t9\tok\t10\t1.25\t0.5\t0.9\t0.8\n"
           "tiny_group_0.5\trisam\t300\t0\t0\t0\t0\ttimeout(300s)\tnan\tnan\tnan\tnan\tnan\n";
  }
  const auto anchors = bench::readRobustAnchorTable(shared.string());
  ASSERT_EQ(anchors.size(), 2u);
  const auto cases = bench::sharedRobustCases(shared.string());
  ASSERT_EQ(cases.size(), 1u);
  std::map<std::string, bench::Reference> optimum;
  auto rows = bench::runRobustBench(cases, optimum, anchors, bench::RobustBatchSettings{},
                                    bench::RobustReplayHooks{}, nullptr);
  ASSERT_EQ(rows.size(), 1u);
  ASSERT_TRUE(rows[0].gnc.has_value());
  EXPECT_DOUBLE_EQ(rows[0].gnc->F_ratio, 1.25);
  ASSERT_TRUE(rows[0].risam.has_value());
  EXPECT_FALSE(rows[0].isam2_cauchy.has_value());
  std::string md = bench::robustMarkdown(rows);
  EXPECT_NE(md.find("| 1.25 · 0.5 · 0.900 · 0.800 · 1.5 | timeout(300s) | — |"), std::string::npos)
      << md;
  EXPECT_NE(md.find("holds no row of tool isam2_cauchy"), std::string::npos) << md;
  EXPECT_EQ(md.find("holds no row of tool risam"), std::string::npos) << md;
  // With an iSAM2 + Cauchy row, its column holds it and the note goes.
  bench::RobustAnchor cauchy;
  cauchy.status = "ok";
  cauchy.F_ratio = 3.5;
  cauchy.ate = 0.25;
  cauchy.precision = 0.5;
  cauchy.recall = 1.0;
  cauchy.total_s = 2.0;
  auto with = anchors;
  with[{"tiny_group_0.5", "isam2_cauchy"}] = cauchy;
  rows = bench::runRobustBench(cases, optimum, with, bench::RobustBatchSettings{},
                               bench::RobustReplayHooks{}, nullptr);
  ASSERT_TRUE(rows[0].isam2_cauchy.has_value());
  md = bench::robustMarkdown(rows);
  EXPECT_NE(md.find("| 3.5 · 0.25 · 0.500 · 1.000 · 2 |"), std::string::npos) << md;
  EXPECT_EQ(md.find("holds no row of tool"), std::string::npos) << md;
  fs::remove_all(shared);
}

// Where the rows stand against issue 14's goals: quality on the rows it covers (10%, 50%, 90%
// random in 2D; a 3D 90% row is not counted), for the replay and the batch, and cost on every
// row with both replays, each naming the rows that miss it.
TEST(RobustBench, GoalsCountTheRowsThatMeetThemAndNameTheOthers) {
  auto figures = [](double F_ratio, double precision, double recall, double total_s, double p99) {
    bench::RobustFigures f;
    f.ok = true;
    f.F_ratio = F_ratio;
    f.score.precision = precision;
    f.score.recall = recall;
    f.total_s = total_s;
    f.latency = LatencySummary{};
    f.latency->p99 = p99;
    return f;
  };
  auto row = [&](const std::string& name, int dim, const std::string& policy, double fraction,
                 const bench::RobustFigures& replay, const bench::RobustFigures& batch) {
    bench::RobustRow r;
    r.c.name = name;
    r.c.policy = policy;
    r.c.fraction = fraction;
    r.dim = dim;
    r.replay = replay;
    r.batch = batch;
    bench::CleanReplayFigures clean;
    clean.total_s = 0.1;
    clean.latency.p99 = 1.0;
    r.clean_replay = clean;
    return r;
  };
  const bench::RobustFigures good = figures(1.0, 1.0, 1.0, 0.15, 1.0);
  const std::vector<bench::RobustRow> rows = {
      row("a_random_0.9", 2, "random", 0.9, good, good),
      row("b_local_0.5", 3, "local", 0.5, figures(1.087, 1.0, 0.977, 0.18, 1.2), good),
      row("c_local_0.9", 3, "local", 0.9, figures(46.0, 0.0, 0.0, 0.25, 1.0),
          figures(46.0, 0.0, 0.0, 0.1, 1.0)),
      row("d_group_0.1", 3, "group", 0.1, figures(1.0, 1.0, 1.0, 0.19, 3.5), good)};
  const std::string goals = bench::robustGoals(rows);
  EXPECT_NE(goals.find("the replay: 2 of 3 rows; misses: b_local_0.5 (F/F* 1.087, P 1.000, "
                       "R 0.977)\n"),
            std::string::npos)
      << goals;
  EXPECT_NE(goals.find("the batch: 3 of 3 rows\n"), std::string::npos) << goals;
  EXPECT_NE(goals.find("clean replay's): 2 of 4 rows; misses: c_local_0.9 (2.50×, p99 1.00×), "
                       "d_group_0.1 (1.90×, p99 3.50×)\n"),
            std::string::npos)
      << goals;
  EXPECT_NE(bench::robustMarkdown(rows).find(goals), std::string::npos);
  EXPECT_EQ(bench::robustGoals({}), "");
}

TEST(RobustBench, GeneratedRowsGoThroughBatchAndTheReplayHooks) {
  const fs::path shared = scratch("generate");
  fs::create_directories(shared / "datasets");
  const PoseGraph2 base = smallManhattan();
  writeG2oFile((shared / "datasets" / "tiny.g2o").string(), base, base.poses);
  bench::GenerationPlan plan;
  plan.bases = {"tiny", "absent"};
  plan.fractions = {0.2};
  plan.policies = {sim::OutlierPolicy::kRandom, sim::OutlierPolicy::kGroup};
  plan.seed = 5;
  std::vector<std::string> missing;
  const fs::path out = shared / "generated";
  fs::create_directories(out);
  const auto cases = bench::generateRobustCases(shared.string(), plan, out.string(), &missing);
  ASSERT_EQ(cases.size(), 2u);
  EXPECT_EQ(missing, std::vector<std::string>{"absent"});
  EXPECT_EQ(cases[0].name, "tiny_random_0.2_seed5");
  EXPECT_EQ(cases[1].name, "tiny_group_0.2_seed5");
  EXPECT_TRUE(fs::exists(cases[1].file));
  EXPECT_EQ(bench::selectCases(cases, "tiny").size(), 2u);
  EXPECT_EQ(bench::selectCases(cases, "tiny_group_0.2_seed5").size(), 1u);

  // The replay hook: an oracle that returns the clean optimum and rejects exactly the labels;
  // the clean replay hook: fixed figures, asked once per base.
  const bench::CleanReference<SE2> ref = bench::cleanReference(base, std::nan(""));
  int clean_calls = 0;
  bench::RobustReplayHooks hooks;
  hooks.robust2 = [&](const PoseGraph2& g) {
    bench::RobustEstimate<SE2> e;
    e.poses = bench::posesByIds(base, ref.optimum, g);  // same ids: the planted graph's order
    e.rejected.assign(g.edges.size(), 0);
    for (int k = base.numEdges(); k < g.numEdges(); ++k) e.rejected[k] = 1;
    e.total_s = 2.0;
    e.latency = LatencySummary{1, 2, 3, 4};
    return e;
  };
  hooks.clean2 = [&](const PoseGraph2& g) {
    ++clean_calls;
    EXPECT_EQ(g.numEdges(), base.numEdges());  // called with the base graph
    bench::CleanReplayFigures c;
    c.total_s = 1.0;
    c.latency.p99 = 1.5;
    return c;
  };
  std::map<std::string, bench::Reference> optimum;
  optimum["tiny"].F_star = ref.F;
  // The batch from the file's vertices, where GNC graduates (from the online replay it stops at
  // its start: TheOnlineStartKeepsTheReplaysRejections).
  bench::RobustBatchSettings from_file;
  from_file.start = bench::BatchStart::kFile;
  const auto rows = bench::runRobustBench(cases, optimum, {}, from_file, hooks, nullptr);
  ASSERT_EQ(rows.size(), 2u);
  EXPECT_EQ(clean_calls, 1);
  for (const bench::RobustRow& r : rows) {
    ASSERT_TRUE(r.error.empty()) << r.error;
    EXPECT_EQ(r.dim, 2);
    EXPECT_EQ(r.loop_closures, sim::countLoopClosures(base));
    EXPECT_EQ(r.false_edges, r.edges - base.numEdges());
    EXPECT_TRUE(r.batch.ok) << r.batch.error;
    EXPECT_GT(r.batch.steps, 0);
    EXPECT_TRUE(std::isfinite(r.batch.F_ratio));
    EXPECT_GE(r.batch.F_ratio, 1.0 - 1e-3);  // nothing beats the clean optimum on its edges
    ASSERT_TRUE(r.replay.has_value());
    ASSERT_TRUE(r.replay->ok) << r.replay->error;
    EXPECT_NEAR(r.replay->F_ratio, 1.0, 1e-9);
    // The bench solved the base as read back from its file (angles written, cos/sin recomputed),
    // the hook's optimum is this test's solve from memory: two LM runs stopped at a relative
    // decrease of 1e-5, a few µm apart.
    EXPECT_NEAR(r.replay->ate, 0.0, 1e-4);
    EXPECT_DOUBLE_EQ(r.replay->score.precision, 1.0);
    EXPECT_DOUBLE_EQ(r.replay->score.recall, 1.0);
    ASSERT_TRUE(r.clean_replay.has_value());
    EXPECT_DOUBLE_EQ(r.clean_replay->total_s, 1.0);
  }
  const std::string md = bench::robustMarkdown(rows);
  EXPECT_NE(md.find("| tiny_group_0.2_seed5 | 2 |"), std::string::npos) << md;
  EXPECT_NE(md.find("total/clean"), std::string::npos) << md;
  EXPECT_NE(md.find("| 2.00 | 2.00 |"), std::string::npos) << md;  // 2 s / 1 s, p99 3 / 1.5
  EXPECT_NE(md.find("- tiny: clean optimum by"), std::string::npos) << md;

  // Without hooks: no replay columns. A case whose file is gone: a row with its error.
  auto broken = cases;
  broken[0].file = (out / "gone.g2o").string();
  const auto plain = bench::runRobustBench(broken, optimum, {}, bench::RobustBatchSettings{},
                                           bench::RobustReplayHooks{}, nullptr);
  ASSERT_EQ(plain.size(), 2u);
  EXPECT_FALSE(plain[0].error.empty());
  EXPECT_TRUE(plain[1].error.empty());
  EXPECT_FALSE(plain[1].replay.has_value());
  EXPECT_EQ(bench::robustMarkdown(plain).find("total/clean"), std::string::npos);
  fs::remove_all(shared);
}

// --batch-start online: the batch starts from the robust online replay and keeps its
// classification: every closure the replay rejected stays rejected unless taken back (none is on
// this graph), and with a planted group the batch rejects exactly the planted closures.
TEST(RobustBench, TheOnlineStartKeepsTheReplaysRejections) {
  const PoseGraph2 base = smallManhattan();
  sim::OutlierOptions o;
  o.fraction = 0.3;
  o.policy = sim::OutlierPolicy::kGroup;
  o.seed = 3;
  const auto planted = sim::addFalseClosures(base, o);
  std::vector<SE2> replayed;
  const cli::OnlineThreshold online =
      cli::onlineThreshold(planted.graph, KernelKind::kTruncatedLeastSquares, {}, &replayed);
  bench::RobustBatchSettings settings;
  settings.start = bench::BatchStart::kOnline;
  const bench::RobustEstimate<SE2> e = bench::robustBatch(planted.graph, settings);
  EXPECT_EQ(e.note.rfind("online: ", 0), 0u) << e.note;
  EXPECT_NE(e.note.find(" 0 taken back"), std::string::npos) << e.note;
  std::vector<char> is_false(planted.graph.edges.size(), 0);
  for (const auto& [i, j] : planted.pairs)
    for (size_t k = 0; k < planted.graph.edges.size(); ++k) {
      const auto& edge = planted.graph.edges[k];
      if (std::min(edge.i, edge.j) == std::min(i, j) && std::max(edge.i, edge.j) == std::max(i, j))
        is_false[k] = 1;
    }
  int held = 0;
  for (size_t k = 0; k < planted.graph.edges.size(); ++k) {
    if (!online.kept[k]) {
      ++held;
      EXPECT_TRUE(e.rejected[k]) << "edge " << k << " the replay rejected came back";
    }
    EXPECT_EQ(e.rejected[k], is_false[k]) << "edge " << k;
  }
  EXPECT_GT(held, 0);
}

// The hooks `arbor bench robust` registers (robust_replay_hooks.h): the robust replay rejects
// the planted group and no true closure (precision and recall 1, F at the clean optimum's to
// 1e-6), its latency and update count come with it, and the clean replay of the base is timed.
TEST(RobustBench, TheRegisteredReplayHooksRunTheRobustReplay) {
  const fs::path shared = scratch("hooks");
  fs::create_directories(shared / "datasets");
  const PoseGraph2 base = smallManhattan();
  writeG2oFile((shared / "datasets" / "tiny.g2o").string(), base, base.poses);
  bench::GenerationPlan plan;
  plan.bases = {"tiny"};
  plan.fractions = {0.2};
  plan.policies = {sim::OutlierPolicy::kGroup};
  plan.seed = 3;
  std::vector<std::string> missing;
  const fs::path out = shared / "generated";
  fs::create_directories(out);
  const auto cases = bench::generateRobustCases(shared.string(), plan, out.string(), &missing);
  ASSERT_EQ(cases.size(), 1u);
  const bench::CleanReference<SE2> ref = bench::cleanReference(base, std::nan(""));
  std::map<std::string, bench::Reference> optimum;
  optimum["tiny"].F_star = ref.F;
  const auto rows =
      bench::runRobustBench(cases, optimum, {}, bench::RobustBatchSettings{},
                            bench::robustReplayHooks(KernelKind::kTruncatedLeastSquares), nullptr);
  ASSERT_EQ(rows.size(), 1u);
  ASSERT_TRUE(rows[0].replay.has_value());
  const bench::RobustFigures& r = *rows[0].replay;
  ASSERT_TRUE(r.ok) << r.error;
  EXPECT_DOUBLE_EQ(r.score.precision, 1.0);
  EXPECT_DOUBLE_EQ(r.score.recall, 1.0);
  EXPECT_NEAR(r.F_ratio, 1.0, 1e-6);
  EXPECT_EQ(r.steps, rows[0].edges);  // one update per edge
  ASSERT_TRUE(r.latency.has_value());
  EXPECT_GT(r.latency->max, 0.0);
  ASSERT_TRUE(rows[0].clean_replay.has_value());
  EXPECT_GT(rows[0].clean_replay->total_s, 0.0);
  fs::remove_all(shared);
}

}  // namespace
}  // namespace arbor
