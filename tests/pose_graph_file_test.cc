// Reading and writing g2o / TORO pose-graph files: record layouts, round trips, error messages
// with line numbers, and the information-matrix policies (refuse, repair, isotropic).
#include <cctype>
#include <charconv>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <iostream>
#include <limits>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include <unistd.h>

#include <gtest/gtest.h>

#include "arbor_slam/core/information.h"
#include "arbor_slam/io/pose_graph_file.h"
#include "arbor_slam/tests/pose_graph_file_support.h"

namespace arbor {
namespace {

using testing::expectSamePose;
using testing::num;
using testing::randomPose;
using testing::readAs;
using testing::readError;
using testing::readText;
constexpr const char* kName = testing::kFileName;

template <int N>
Eigen::Matrix<double, N, N> randomInformation(std::mt19937_64& rng) {
  return testing::randomSpd<N>(rng);
}

// A graph with non-contiguous ascending ids, a chain plus random loop closures, one fixed pose.
template <class G>
PoseGraph<G> randomGraph(std::mt19937_64& rng, int num_poses, int num_loops) {
  PoseGraph<G> graph;
  Key id = 2;
  for (int k = 0; k < num_poses; ++k) {
    id += 1 + static_cast<Key>(rng() % 5);
    graph.ids.push_back(id);
    graph.index[id] = k;
    graph.poses.push_back(randomPose<G>(rng, 3.0));
  }
  for (int k = 0; k + 1 < num_poses + num_loops; ++k) {
    int i = k, j = k + 1;
    if (k + 1 >= num_poses) {
      i = static_cast<int>(rng() % num_poses);
      j = static_cast<int>(rng() % num_poses);
      if (i == j) j = (i + 1) % num_poses;
    }
    graph.edges.push_back(
        RelativePoseEdge<G>::make(i, j, randomPose<G>(rng, 1.0), randomInformation<G::kDoF>(rng)));
  }
  graph.fixed = {1};
  graph.has_initial_estimate = true;
  return graph;
}

template <class G>
void expectSameGraph(const PoseGraph<G>& expected, const PoseGraph<G>& actual,
                     const std::vector<G>& expected_poses) {
  EXPECT_EQ(expected.ids, actual.ids);
  EXPECT_EQ(expected.index, actual.index);
  EXPECT_EQ(expected.fixed, actual.fixed);
  ASSERT_EQ(expected_poses.size(), actual.poses.size());
  for (std::size_t k = 0; k < expected_poses.size(); ++k) {
    expectSamePose(expected_poses[k], actual.poses[k]);
  }
  ASSERT_EQ(expected.edges.size(), actual.edges.size());
  for (std::size_t k = 0; k < expected.edges.size(); ++k) {
    const auto& a = expected.edges[k];
    const auto& b = actual.edges[k];
    EXPECT_EQ(a.i, b.i);
    EXPECT_EQ(a.j, b.j);
    expectSamePose(a.measurement, b.measurement);
    EXPECT_TRUE((a.information.array() == b.information.array()).all()) << "edge " << k;
  }
}

template <class G>
PoseGraph<G> writeAndRead(const PoseGraph<G>& graph, const std::vector<G>& poses,
                          std::string* text = nullptr) {
  std::ostringstream out;
  writeG2o(out, graph, poses);
  if (text) *text = out.str();
  return readAs<G>(out.str());
}

std::string sharedDataset(const std::string& file) {
  return std::string(ARBOR_SHARED_DIR) + "/datasets/" + file;
}

// ---------------------------------------------------------------------------------------------
// Record layouts.

TEST(PoseGraphFile, Reads2DVerticesEdgesAndG2oInformationOrder) {
  ReadReport report;
  const auto graph = readAs<SE2>(
      "VERTEX_SE2 0 0 0 0\n"
      "VERTEX_SE2 1 1 0.5 0.25\n"
      "EDGE_SE2 0 1 1.5 -0.5 0.75 11 12 13 22 23 33\n",
      {}, &report);
  EXPECT_TRUE(graph.has_initial_estimate);
  ASSERT_EQ(graph.numPoses(), 2);
  EXPECT_EQ(graph.poses[1].x(), 1.0);
  EXPECT_EQ(graph.poses[1].y(), 0.5);
  EXPECT_NEAR(graph.poses[1].angle(), 0.25, 1e-15);
  ASSERT_EQ(graph.numEdges(), 1);
  const auto& e = graph.edges[0];
  EXPECT_EQ(e.i, 0);
  EXPECT_EQ(e.j, 1);
  EXPECT_EQ(e.measurement.x(), 1.5);
  EXPECT_EQ(e.measurement.y(), -0.5);
  EXPECT_NEAR(e.measurement.angle(), 0.75, 1e-15);
  Eigen::Matrix3d expected;
  expected << 11, 12, 13, 12, 22, 23, 13, 23, 33;
  EXPECT_EQ(e.information, expected);
  EXPECT_EQ(report.edge_lines, std::vector<int>{3});
  EXPECT_TRUE(report.warnings.empty());
}

TEST(PoseGraphFile, ToroAndG2oInformationOrdersGiveTheSameOmega) {
  // Ω = [11 12 13; 12 22 23; 13 23 33]: g2o lists I11 I12 I13 I22 I23 I33, TORO I11 I12 I22 I33 I13
  // I23.
  const auto g2o = readAs<SE2>(
      "VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 1 0 0\n"
      "EDGE_SE2 0 1 1 2 0.5 11 12 13 22 23 33\n");
  const auto toro = readAs<SE2>(
      "VERTEX2 0 0 0 0\nVERTEX2 1 1 0 0\n"
      "EDGE2 0 1 1 2 0.5 11 12 22 33 13 23\n");
  ASSERT_EQ(toro.numEdges(), 1);
  EXPECT_EQ(g2o.edges[0].information, toro.edges[0].information);
  EXPECT_EQ(toro.edges[0].information(1, 1), 22.0);
  EXPECT_EQ(toro.edges[0].information(0, 2), 13.0);
  expectSameGraph(g2o, toro, g2o.poses);

  // The same six numbers read in the other order are another matrix.
  const auto swapped = readAs<SE2>(
      "VERTEX2 0 0 0 0\nVERTEX2 1 1 0 0\n"
      "EDGE2 0 1 1 2 0.5 11 12 13 22 23 33\n",
      {InformationPolicy::kRepair});
  EXPECT_NE(swapped.edges[0].information, g2o.edges[0].information);
}

TEST(PoseGraphFile, Reads3DUpperTriangleInformationAndQuaternions) {
  std::mt19937_64 rng(7);
  const Eigen::Matrix<double, 6, 6> omega = randomInformation<6>(rng);
  std::string info;
  for (int r = 0; r < 6; ++r) {
    for (int c = r; c < 6; ++c) info += " " + num(omega(r, c));
  }
  const Eigen::Quaterniond q = Eigen::Quaterniond(0.9, 0.1, -0.3, 0.2).normalized();
  const std::string quat = num(q.x()) + " " + num(q.y()) + " " + num(q.z()) + " " + num(q.w());
  const auto graph = readAs<SE3>(
      "VERTEX_SE3:QUAT 4 0 0 0 0 0 0 1\n"
      "VERTEX_SE3:QUAT 8 1 2 3 " +
      quat +
      "\n"
      "EDGE_SE3:QUAT 4 8 0.5 -1 2 " +
      quat + info + "\n");
  ASSERT_EQ(graph.numEdges(), 1);
  EXPECT_EQ(graph.edges[0].information, omega);
  EXPECT_EQ(graph.edges[0].measurement.translation(), Eigen::Vector3d(0.5, -1, 2));
  EXPECT_LE((graph.edges[0].measurement.quaternion().coeffs() - q.coeffs()).norm(), 1e-15);
  EXPECT_EQ(graph.poses[1].translation(), Eigen::Vector3d(1, 2, 3));
  EXPECT_LE((graph.poses[1].quaternion().coeffs() - q.coeffs()).norm(), 1e-15);
}

TEST(PoseGraphFile, EdgesOnlyFileLeavesPosesIdentityWithoutInitialEstimate) {
  ReadReport report;
  const auto graph = readAs<SE2>(
      "EDGE_SE2 9 20 1 0 0 1 0 0 1 0 1\n"
      "EDGE_SE2 5 9 1 0 0 1 0 0 1 0 1\n"
      "EDGE_SE2 5 20 2 0 0 1 0 0 1 0 1\n",
      {}, &report);
  EXPECT_FALSE(graph.has_initial_estimate);
  EXPECT_EQ(graph.ids, (std::vector<Key>{5, 9, 20}));
  for (const auto& x : graph.poses) {
    EXPECT_EQ(x.translation(), Eigen::Vector2d::Zero());
    EXPECT_EQ(x.angle(), 0.0);
  }
  ASSERT_EQ(graph.numEdges(), 3);
  EXPECT_EQ(graph.edges[0].i, 1);
  EXPECT_EQ(graph.edges[0].j, 2);
  EXPECT_EQ(graph.edges[1].i, 0);
  EXPECT_EQ(graph.edges[2].j, 2);
  EXPECT_EQ(report.edge_lines, (std::vector<int>{1, 2, 3}));
}

TEST(PoseGraphFile, NonContiguousIdsGetAscendingDenseIndices) {
  const auto graph = readAs<SE2>(
      "VERTEX_SE2 10 10 0 0\n"
      "VERTEX_SE2 3 3 0 0\n"
      "EDGE_SE2 10 3 1 0 0 1 0 0 1 0 1\n"
      "EDGE_SE2 3 7 1 0 0 1 0 0 1 0 1\n"
      "VERTEX_SE2 7 7 0 0\n");  // a VERTEX may follow its edges
  EXPECT_EQ(graph.ids, (std::vector<Key>{3, 7, 10}));
  ASSERT_EQ(graph.index.size(), 3u);
  for (int k = 0; k < 3; ++k) {
    EXPECT_EQ(graph.index.at(graph.ids[k]), k);
    EXPECT_EQ(graph.poses[k].x(), static_cast<double>(graph.ids[k]));
  }
  EXPECT_EQ(graph.edges[0].i, 2);
  EXPECT_EQ(graph.edges[0].j, 0);
  EXPECT_EQ(graph.edges[1].i, 0);
  EXPECT_EQ(graph.edges[1].j, 1);
}

TEST(PoseGraphFile, SkipsCommentsBlankLinesAndCarriageReturns) {
  ReadReport report;
  const auto graph = readAs<SE2>(
      "# a header comment\n"
      "\n"
      "   \t \r\n"
      "VERTEX_SE2 0 0 0 0   # a trailing comment\r\n"
      "\tVERTEX_SE2  1  1 0 0\r\n"
      "  # an indented comment\n"
      "EDGE_SE2 0 1 1 0 0 1 0 0 1 0 1",  // no final newline
      {}, &report);
  EXPECT_EQ(graph.numPoses(), 2);
  EXPECT_EQ(graph.numEdges(), 1);
  EXPECT_EQ(report.edge_lines, std::vector<int>{7});
}

TEST(PoseGraphFile, FixSetsFixedPosesByDenseIndex) {
  ReadReport report;
  const auto graph = readAs<SE2>(
      "FIX 30\n"  // may precede its VERTEX
      "VERTEX_SE2 10 0 0 0\n"
      "VERTEX_SE2 20 1 0 0\n"
      "VERTEX_SE2 30 2 0 0\n"
      "FIX 10 20\n"
      "FIX 30\n"
      "EDGE_SE2 10 20 1 0 0 1 0 0 1 0 1\n",
      {}, &report);
  EXPECT_EQ(graph.fixed, (std::vector<int>{2, 0, 1}));
  EXPECT_EQ(graph.gaugeIndices(), graph.fixed);
  ASSERT_EQ(report.warnings.size(), 1u);  // the repeated FIX 30
  EXPECT_NE(report.warnings[0].find("test.g2o:6:"), std::string::npos) << report.warnings[0];

  const auto none = readAs<SE2>("EDGE_SE2 4 5 1 0 0 1 0 0 1 0 1\n");
  EXPECT_TRUE(none.fixed.empty());
  EXPECT_EQ(none.gaugeIndices(), std::vector<int>{0});
}

TEST(PoseGraphFile, RenormalisesFarQuaternionsWithAWarning) {
  ReadReport report;
  const auto graph = readAs<SE3>(
      "VERTEX_SE3:QUAT 0 0 0 0 0 0 0 2\n"
      "VERTEX_SE3:QUAT 1 1 0 0 0 0 0 1.0005\n"  // within 1e-3: silent
      "EDGE_SE3:QUAT 0 1 1 0 0 0 0 0.6 0.9 "
      "1 0 0 0 0 0 1 0 0 0 0 1 0 0 0 1 0 0 1 0 1\n",
      {}, &report);
  ASSERT_EQ(report.warnings.size(), 2u);
  EXPECT_NE(report.warnings[0].find("test.g2o:1: quaternion norm 2"), std::string::npos)
      << report.warnings[0];
  EXPECT_NE(report.warnings[1].find("test.g2o:3:"), std::string::npos) << report.warnings[1];
  EXPECT_NE(report.warnings[1].find("renormalised"), std::string::npos);
  EXPECT_NEAR(graph.poses[0].quaternion().w(), 1.0, 1e-15);
  EXPECT_NEAR(graph.edges[0].measurement.quaternion().norm(), 1.0, 1e-15);
  EXPECT_NEAR(graph.edges[0].measurement.quaternion().z(), 0.6 / std::hypot(0.6, 0.9), 1e-15);
}

// ---------------------------------------------------------------------------------------------
// Errors.

struct MalformedCase {
  std::string text;
  int line;
  std::string message;
};

TEST(PoseGraphFile, MalformedLinesNameTheLineAndTheProblem) {
  const std::string v2 = "VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 1 0 0\n";  // lines 1–2
  const std::string v3 = "VERTEX_SE3:QUAT 0 0 0 0 0 0 0 1\nVERTEX_SE3:QUAT 1 1 0 0 0 0 0 1\n";
  const std::string info2 = " 1 0 0 1 0 1";
  const std::string info3 = " 1 0 0 0 0 0 1 0 0 0 0 1 0 0 0 1 0 0 1 0 1";
  const std::vector<MalformedCase> cases = {
      {"FOO 1 2 3\n", 1, "unknown tag 'FOO'"},
      {v2 + "VERTEX_se2 2 0 0 0\n", 3, "unknown tag 'VERTEX_se2'"},
      {v2 + "VERTEX_XY 2 0 0\n", 3,
       "unknown tag 'VERTEX_XY' (landmarks are not supported: Arbor's variables are poses only; "
       "a measurement of a known point is a factor of your own, docs/design.md"},
      {v2 + "EDGE_SE2_XY 0 2 1 0 1 0 1\n", 3, "unknown tag 'EDGE_SE2_XY' (landmarks are not"},
      {"VERTEX_SE2 0 1 2\n", 1, "too few fields for VERTEX_SE2: expected 4 after the tag"},
      {"VERTEX_SE2 0 1 2 3 4\n", 1, "too many fields for VERTEX_SE2: expected 4"},
      {v2 + "EDGE_SE2 0 1 1 0 0 1 0 0 1 0\n", 3, "too few fields for EDGE_SE2: expected 11"},
      {v2 + "EDGE2 0 1 1 0 0 1 0 0 1 0 1 7\n", 3, "too many fields for EDGE2"},
      {v3 + "EDGE_SE3:QUAT 0 1 0 0 0 0 0 0 1" + info3 + " 1\n", 3,
       "too many fields for EDGE_SE3:QUAT: expected 30"},
      {"VERTEX_SE2 0 1 abc 3\n", 1, "field 4 of VERTEX_SE2 ('abc') is not a number"},
      {"VERTEX_SE2 0 1 1.5x 3\n", 1, "('1.5x') is not a number"},
      {"VERTEX_SE2 0 1 +-1 3\n", 1, "('+-1') is not a number"},
      {"VERTEX_SE2 0 1 nan 3\n", 1, "('nan') is not finite"},
      {"VERTEX_SE2 0 1 -inf 3\n", 1, "('-inf') is not finite"},
      {"VERTEX_SE2 0 1 1e999 3\n", 1, "('1e999') is out of the range"},
      {"VERTEX_SE2 1.5 0 0 0\n", 1, "('1.5') is not a non-negative integer id"},
      {"VERTEX_SE2 x 0 0 0\n", 1, "('x') is not a non-negative integer id"},
      {"VERTEX_SE2 -1 0 0 0\n", 1, "('-1') is a negative id"},
      {v2 + "EDGE_SE2 0 -4 1 0 0" + info2 + "\n", 3, "('-4') is a negative id"},
      {v2 + "VERTEX_SE2 1 2 0 0\n", 3, "duplicate VERTEX id 1 (first at line 2)"},
      {v2 + "EDGE_SE2 1 1 1 0 0" + info2 + "\n", 3, "self-loop edge 1 -> 1"},
      {v2 + "EDGE_SE2 0 1 1 0 0" + info2 + "\nEDGE_SE2 0 7 1 0 0" + info2 + "\n", 4,
       "names id 7, which has no VERTEX"},
      {v2 + "EDGE_SE2 0 1 1 0 0 1 0 0 nan 0 1\n", 3, "('nan') is not finite"},
      {"VERTEX_SE3:QUAT 0 0 0 0 0 0 0 0\n", 1, "quaternion (qx qy qz qw) = (0 0 0 0) is zero"},
      {v3 + "EDGE_SE3:QUAT 0 1 0 0 0 0 0 0 0" + info3 + "\n", 3, "is zero"},
      {"VERTEX_SE3:QUAT 0 0 0 0 1e308 -1e308 0 1\n", 1,
       "quaternion (qx qy qz qw) = (1e+308 -1e+308 0 1) overflows (norm inf)"},
      {v3 + "EDGE_SE3:QUAT 0 1 0 0 0 nan 0 0 1" + info3 + "\n", 3, "('nan') is not finite"},
      {v2 + "FIX 9\n", 3, "FIX of unknown id 9"},
      {"EDGE_SE2 0 1 1 0 0" + info2 + "\nFIX 0 2\n", 2, "FIX of unknown id 2"},
      {v2 + "FIX\n", 3, "too few fields for FIX"},
      {v2 + "FIX 1 -2\n", 3, "('-2') is a negative id"},
      {v2 + "VERTEX_SE3:QUAT 2 0 0 0 0 0 0 1\n", 3,
       "mixes 2D and 3D records: VERTEX_SE3:QUAT after VERTEX_SE2 at line 1"},
      {v3 + "EDGE2 0 1 1 0 0" + info2 + "\n", 3, "mixes 2D and 3D records: EDGE2"},
      // Finite but so large that F = Σ eᵀΩe would overflow (an edge of 1e308 m once made a
      // whole replay's estimate NaN).
      {"VERTEX_SE2 0 1e16 0 0\n", 1,
       "translation component of magnitude 1e+16 beyond the largest accepted (1e+15)"},
      {v2 + "EDGE_SE2 0 1 -1e308 0 0" + info2 + "\n", 3,
       "translation component of magnitude 1e+308 beyond the largest accepted"},
      {v3 + "EDGE_SE3:QUAT 0 1 0 0 2e15 0 0 0 1" + info3 + "\n", 3,
       "translation component of magnitude 2e+15"},
      {v2 + "EDGE_SE2 0 1 1 0 0 1e308 0 0 1 0 1\n", 3,
       "information matrix has an entry of magnitude 1e+308, beyond the largest accepted"},
  };
  for (const auto& c : cases) {
    const std::string message = readError(c.text);
    const std::string where = std::string(kName) + ":" + std::to_string(c.line) + ": ";
    EXPECT_EQ(message.rfind(where, 0), 0u) << "input:\n" << c.text << "message: " << message;
    EXPECT_NE(message.find(c.message), std::string::npos)
        << "input:\n"
        << c.text << "message: " << message << "\nwanted: " << c.message;
  }
}

TEST(PoseGraphFile, FileWithoutRecordsIsAnError) {
  EXPECT_EQ(readError(""), "test.g2o: no VERTEX or EDGE records");
  EXPECT_EQ(readError("# only a comment\n\n"), "test.g2o: no VERTEX or EDGE records");
  EXPECT_EQ(readError("FIX 0\n"), "test.g2o: no VERTEX or EDGE records");
}

TEST(PoseGraphFile, MissingFileNamesThePath) {
  const std::string path = "/nonexistent/arbor/graph.g2o";
  try {
    readPoseGraphFile(path);
    FAIL() << "no error";
  } catch (const FileError& error) {
    EXPECT_NE(std::string(error.what()).find(path + ": cannot open"), std::string::npos)
        << error.what();
  }
}

// ---------------------------------------------------------------------------------------------
// Information policies on a small graph with two indefinite Ω (lines 5 and 7).

const char kIndefinite2D[] =
    "VERTEX_SE2 0 0 0 0\n"
    "VERTEX_SE2 1 1 0 0\n"
    "VERTEX_SE2 2 2 0 0\n"
    "EDGE_SE2 0 1 1 0 0 4 1 0 9 0 2\n"
    "EDGE_SE2 0 1 1 0 0 1 2 0 1 0 1\n"  // eigenvalues −1, 1, 3
    "EDGE_SE2 1 2 1 0 0 4 0.5 0.1 2 0 1\n"
    "EDGE_SE2 0 2 2 0 0 1 0 0 1 0 -3\n";  // eigenvalues 1, 1, −3

TEST(PoseGraphFile, IndefiniteInformationIsRefusedByDefaultInOneError) {
  const std::string message = readError(kIndefinite2D);
  EXPECT_EQ(message,
            "test.g2o: 2 of 4 edges have an information matrix that is not positive definite; "
            "first at lines 5, 7; use --information repair or isotropic");

  // More than five: the first five lines, then an ellipsis.
  std::string text = "VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 1 0 0\n";
  for (int k = 0; k < 7; ++k) text += "EDGE_SE2 0 1 1 0 0 1 2 0 1 0 1\n";
  EXPECT_NE(readError(text).find("7 of 7 edges have an information matrix that is not positive "
                                 "definite; first at lines 3, 4, 5, 6, 7, …;"),
            std::string::npos)
      << readError(text);
}

TEST(PoseGraphFile, RepairReplacesOnlyTheIndefiniteInformation) {
  ReadReport report;
  const auto graph = readAs<SE2>(kIndefinite2D, {InformationPolicy::kRepair}, &report);
  EXPECT_EQ(report.repaired, 2);
  EXPECT_EQ(report.made_isotropic, 0);
  EXPECT_EQ(report.edge_lines, (std::vector<int>{4, 5, 6, 7}));
  ASSERT_EQ(graph.numEdges(), 4);
  Eigen::Matrix3d good, bad;
  good << 4, 1, 0, 1, 9, 0, 0, 0, 2;
  bad << 1, 2, 0, 2, 1, 0, 0, 0, 1;
  EXPECT_EQ(graph.edges[0].information, good);
  EXPECT_TRUE(graph.edges[1].information.isApprox(nearestPositiveDefinite(bad), 1e-12));
  for (const auto& e : graph.edges) EXPECT_EQ(informationProblem(e.information), "");
}

TEST(PoseGraphFile, IsotropicReplacesEveryInformation) {
  ReadReport report;
  const auto graph = readAs<SE2>(kIndefinite2D, {InformationPolicy::kIsotropic}, &report);
  EXPECT_EQ(report.made_isotropic, 4);
  EXPECT_EQ(report.repaired, 2);
  Eigen::Matrix3d good;
  good << 4, 1, 0, 1, 9, 0, 0, 0, 2;
  EXPECT_TRUE(graph.edges[0].information.isApprox(isotropicInformation(good, 2), 1e-12));
  for (const auto& e : graph.edges) {
    const Eigen::Matrix3d& omega = e.information;
    EXPECT_EQ(omega(0, 0), omega(1, 1));
    EXPECT_GT(omega(0, 0), 0.0);
    EXPECT_GT(omega(2, 2), 0.0);
    EXPECT_EQ((omega - Eigen::Matrix3d(omega.diagonal().asDiagonal())).cwiseAbs().maxCoeff(), 0.0);
  }
}

// The first edges of cubicle.g2o: its third edge (1 → 2, file line 5753) is indefinite.
TEST(PoseGraphFile, CubicleLikeIndefiniteEdgeIn3D) {
  const std::string text =
      "VERTEX_SE3:QUAT 0 0 0 0 0 0 0 1\n"
      "VERTEX_SE3:QUAT 1 0 0 0 0 0 0 1\n"
      "VERTEX_SE3:QUAT 2 -0.000205 0.000265 0 0 0 0.00012 1\n"
      "EDGE_SE3:QUAT 0 1 0 0 0 0 0 0 1 100 0 0 0 0 0 100 0 0 0 0 4e+06 0 0 0 1e+06 0 0 1e+06 0 "
      "6.25\n"
      "EDGE_SE3:QUAT 1 2 0 0 0 0 0 0 1 100 0 0 0 0 0 100 0 0 0 0 4e+06 0 0 0 1e+06 0 0 1e+06 0 "
      "6.25\n"
      "EDGE_SE3:QUAT 1 2 -0.000106623 0.000270013 0 0 0 0.000126644 1 2.46483e+06 5.3553e+06 0 0 0 "
      "0 1.52034e+07 0 0 0 0 10 84022.3 132748 0 10 0 0 10 0 91520.2\n";
  const std::string message = readError(text);
  EXPECT_NE(message.find("test.g2o: 1 of 3 edges have an information matrix that is not "
                         "positive definite; first at line 6;"),
            std::string::npos)
      << message;
  ReadReport report;
  const auto repaired = readAs<SE3>(text, {InformationPolicy::kRepair}, &report);
  EXPECT_EQ(report.repaired, 1);
  EXPECT_EQ(informationProblem(repaired.edges[2].information), "");
  const auto isotropic = readAs<SE3>(text, {InformationPolicy::kIsotropic}, &report);
  EXPECT_EQ(report.repaired, 1);
  EXPECT_EQ(report.made_isotropic, 3);
  EXPECT_EQ(isotropic.edges[0].information(0, 0), isotropic.edges[0].information(2, 2));
  EXPECT_EQ(isotropic.edges[0].information(3, 3), isotropic.edges[0].information(5, 5));
}

// ---------------------------------------------------------------------------------------------
// Writing.

template <class G>
class RoundTripTest : public ::testing::Test {};
using Groups = ::testing::Types<SE2, SE3>;
TYPED_TEST_SUITE(RoundTripTest, Groups);

TYPED_TEST(RoundTripTest, WrittenFileReadsBackIdentically) {
  using G = TypeParam;
  std::mt19937_64 rng(11);
  const PoseGraph<G> graph = randomGraph<G>(rng, 40, 25);
  std::string text;
  ReadReport report;
  std::ostringstream out;
  writeG2o(out, graph, graph.poses);
  text = out.str();
  const PoseGraph<G> back = readAs<G>(text, {}, &report);
  EXPECT_TRUE(back.has_initial_estimate);
  expectSameGraph(graph, back, graph.poses);
  ASSERT_EQ(report.edge_lines.size(), graph.edges.size());
  EXPECT_EQ(report.edge_lines[0], graph.numPoses() + 1 + 1);  // after the VERTEX and FIX lines
  EXPECT_NE(text.find("FIX " + std::to_string(graph.ids[1]) + "\n"), std::string::npos);

  // Writing a different pose vector than graph.poses writes those poses.
  std::vector<G> other;
  for (int k = 0; k < graph.numPoses(); ++k) other.push_back(randomPose<G>(rng, 1.0));
  expectSameGraph(graph, writeAndRead(graph, other), other);
}

TYPED_TEST(RoundTripTest, WriteFileThenReadFile) {
  using G = TypeParam;
  std::mt19937_64 rng(5);
  const PoseGraph<G> graph = randomGraph<G>(rng, 10, 4);
  const std::filesystem::path path =
      std::filesystem::temp_directory_path() /
      ("arbor_io_test_" + std::to_string(::getpid()) + "_" + std::to_string(G::kDoF) + ".g2o");
  writeG2oFile(path.string(), graph, graph.poses);
  const AnyPoseGraph any = readPoseGraphFile(path.string());
  std::filesystem::remove(path);
  ASSERT_TRUE(std::holds_alternative<PoseGraph<G>>(any));
  expectSameGraph(graph, std::get<PoseGraph<G>>(any), graph.poses);
  EXPECT_THROW(writeG2oFile("/nonexistent/arbor/out.g2o", graph, graph.poses), FileError);
}

TYPED_TEST(RoundTripTest, WriterRefusesMismatchedOrNonFinitePoses) {
  using G = TypeParam;
  std::mt19937_64 rng(3);
  const PoseGraph<G> graph = randomGraph<G>(rng, 5, 2);
  std::ostringstream out;
  std::vector<G> poses = graph.poses;
  poses.pop_back();
  EXPECT_THROW(writeG2o(out, graph, poses), std::invalid_argument);
  poses = graph.poses;
  typename G::Tangent tau = G::Tangent::Zero();
  tau(0) = std::numeric_limits<double>::quiet_NaN();
  poses[2] = poses[2].retract(tau);
  EXPECT_THROW(writeG2o(out, graph, poses), std::invalid_argument);
}

// ---------------------------------------------------------------------------------------------
// Shared datasets (skipped when ../shared is absent).

struct DatasetCase {
  std::string file;
  int dim;
  int poses;
  int edges;
  bool has_vertices;
};

std::ostream& operator<<(std::ostream& os, const DatasetCase& c) { return os << c.file; }

class SharedDatasetTest : public ::testing::TestWithParam<DatasetCase> {};

TEST_P(SharedDatasetTest, ParsesWithTheDocumentedCounts) {
  const DatasetCase& c = GetParam();
  const std::string path = sharedDataset(c.file);
  if (!std::filesystem::exists(path)) GTEST_SKIP() << "shared dataset absent: " << path;
  ReadOptions options;
  if (c.file == "cubicle.g2o") options.information = InformationPolicy::kRepair;
  ReadReport report;
  const auto start = std::chrono::steady_clock::now();
  const AnyPoseGraph any = readPoseGraphFile(path, options, &report);
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  std::cout << "[ info     ] " << c.file << " read in " << seconds * 1e3 << " ms\n";
  ASSERT_EQ(static_cast<int>(any.index()), c.dim == 2 ? 0 : 1);
  std::visit(
      [&](const auto& graph) {
        EXPECT_EQ(graph.numPoses(), c.poses);
        EXPECT_EQ(graph.numEdges(), c.edges);
        EXPECT_EQ(graph.has_initial_estimate, c.has_vertices);
        EXPECT_EQ(static_cast<int>(report.edge_lines.size()), c.edges);
      },
      any);
  EXPECT_TRUE(report.warnings.empty()) << report.warnings.front();
}

TEST_P(SharedDatasetTest, WritesBackAsG2oAndReadsIdentically) {
  const DatasetCase& c = GetParam();
  const std::string path = sharedDataset(c.file);
  if (!std::filesystem::exists(path)) GTEST_SKIP() << "shared dataset absent: " << path;
  ReadOptions options;
  if (c.file == "cubicle.g2o") options.information = InformationPolicy::kRepair;
  const AnyPoseGraph any = readPoseGraphFile(path, options);
  std::visit(
      [&](const auto& graph) {
        std::string text;
        auto back = writeAndRead(graph, graph.poses, &text);
        EXPECT_TRUE(back.has_initial_estimate);
        expectSameGraph(graph, back, graph.poses);
        EXPECT_EQ(text.find("EDGE2 "), std::string::npos);  // TORO is written back as g2o
        EXPECT_EQ(text.find("VERTEX2 "), std::string::npos);
      },
      any);
}

INSTANTIATE_TEST_SUITE_P(Datasets, SharedDatasetTest,
                         ::testing::Values(DatasetCase{"intel.g2o", 2, 1728, 2512, true},
                                           DatasetCase{"MIT.g2o", 2, 808, 827, true},
                                           DatasetCase{"M3500.g2o", 2, 3500, 5453, true},
                                           DatasetCase{"M3500a.g2o", 2, 3500, 5453, true},
                                           DatasetCase{"M3500b.g2o", 2, 3500, 5453, true},
                                           DatasetCase{"M3500c.g2o", 2, 3500, 5453, true},
                                           DatasetCase{"manhattan.g2o", 2, 3500, 5453, false},
                                           DatasetCase{"sphere_bignoise_vertex3.g2o", 3, 2200, 8647,
                                                       true},
                                           DatasetCase{"torus3D.g2o", 3, 5000, 9048, true},
                                           DatasetCase{"parking-garage.g2o", 3, 1661, 6275, true},
                                           DatasetCase{"cubicle.g2o", 3, 5750, 16869, true},
                                           DatasetCase{"smallGrid3D.g2o", 3, 125, 297, true},
                                           DatasetCase{"tinyGrid3D.g2o", 3, 9, 11, true}),
                         [](const ::testing::TestParamInfo<DatasetCase>& info) {
                           std::string name = info.param.file.substr(0, info.param.file.find('.'));
                           for (char& ch : name) {
                             if (!std::isalnum(static_cast<unsigned char>(ch))) ch = '_';
                           }
                           return name;
                         });

TEST(PoseGraphFile, CubicleIsRefusedByDefault) {
  const std::string path = sharedDataset("cubicle.g2o");
  if (!std::filesystem::exists(path)) GTEST_SKIP() << "shared dataset absent: " << path;
  try {
    readPoseGraphFile(path);
    FAIL() << "cubicle.g2o was accepted";
  } catch (const FileError& error) {
    const std::string message = error.what();
    EXPECT_NE(message.find(path + ": 5021 of 16869 edges have an information matrix that is not "
                                  "positive definite; first at lines 5753, "),
              std::string::npos)
        << message;
    EXPECT_NE(message.find("--information repair or isotropic"), std::string::npos) << message;
  }
}

TEST(PoseGraphFile, CubicleRepairedAndIsotropicCounts) {
  const std::string path = sharedDataset("cubicle.g2o");
  if (!std::filesystem::exists(path)) GTEST_SKIP() << "shared dataset absent: " << path;
  ReadReport report;
  const auto repaired =
      std::get<PoseGraph3>(readPoseGraphFile(path, {InformationPolicy::kRepair}, &report));
  EXPECT_EQ(report.repaired, 5021);
  EXPECT_EQ(report.made_isotropic, 0);
  EXPECT_EQ(repaired.numEdges(), 16869);
  for (const auto& e : repaired.edges) ASSERT_EQ(informationProblem(e.information), "");

  const auto isotropic =
      std::get<PoseGraph3>(readPoseGraphFile(path, {InformationPolicy::kIsotropic}, &report));
  EXPECT_EQ(report.made_isotropic, 16869);
  EXPECT_EQ(report.repaired, 5021);
  for (const auto& e : isotropic.edges) {
    ASSERT_EQ(e.information(0, 0), e.information(1, 1));
    ASSERT_EQ(e.information(3, 3), e.information(5, 5));
    ASSERT_EQ(e.information(0, 3), 0.0);
  }
}

}  // namespace
}  // namespace arbor
