// Trajectory exports (io/trajectory_writer.h): TUM and KITTI lines parsed back, orientation
// conversions on known rotations, id order, errors.
#include <cmath>
#include <cstdio>
#include <fstream>
#include <random>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <Eigen/Core>
#include <Eigen/Geometry>

#include "arbor_slam/io/pose_graph_file.h"
#include "arbor_slam/io/trajectory_writer.h"
#include "random_graphs.h"

namespace arbor {
namespace {

constexpr double kPi = 3.14159265358979323846;

/// Every line of `text` as its numbers.
std::vector<std::vector<double>> parseLines(const std::string& text) {
  std::vector<std::vector<double>> rows;
  std::istringstream in(text);
  std::string line;
  while (std::getline(in, line)) {
    std::istringstream fields(line);
    std::vector<double> row;
    double v;
    while (fields >> v) row.push_back(v);
    EXPECT_TRUE(fields.eof()) << "not a number in: " << line;
    rows.push_back(row);
  }
  return rows;
}

template <class G>
std::string written(TrajectoryFormat format, const std::vector<Key>& ids,
                    const std::vector<G>& poses) {
  std::ostringstream out;
  writeTrajectory(out, format, ids, poses);
  return out.str();
}

TEST(TrajectoryWriter, Tum2DIsAYawAboutZ) {
  const std::vector<double> angles = {0.0, kPi / 2, kPi, -kPi / 2, 0.3, -2.5};
  std::vector<SE2> poses;
  std::vector<Key> ids;
  for (size_t k = 0; k < angles.size(); ++k) {
    poses.emplace_back(1.5 * k, -0.25 * k, angles[k]);
    ids.push_back(static_cast<Key>(10 * k + 3));
  }
  const auto rows = parseLines(written(TrajectoryFormat::kTum, ids, poses));
  ASSERT_EQ(rows.size(), poses.size());
  for (size_t k = 0; k < rows.size(); ++k) {
    const auto& r = rows[k];
    ASSERT_EQ(r.size(), 8u);
    EXPECT_EQ(r[0], static_cast<double>(ids[k]));  // timestamp = the pose id
    EXPECT_EQ(r[1], poses[k].x());
    EXPECT_EQ(r[2], poses[k].y());
    EXPECT_EQ(r[3], 0.0);
    EXPECT_EQ(r[4], 0.0);
    EXPECT_EQ(r[5], 0.0);
    EXPECT_NEAR(r[6] * r[6] + r[7] * r[7], 1.0, 1e-15);
    EXPECT_NEAR(wrapAngle(2 * std::atan2(r[6], r[7]) - poses[k].angle()), 0.0, 1e-14);
  }
  // A quarter turn: q = (0, 0, sin π/4, cos π/4).
  EXPECT_NEAR(rows[1][6], std::sqrt(0.5), 1e-15);
  EXPECT_NEAR(rows[1][7], std::sqrt(0.5), 1e-15);
}

TEST(TrajectoryWriter, Kitti2DRotatesAboutZ) {
  const std::vector<SE2> poses = {SE2(2.0, 3.0, kPi / 2), SE2(-1.0, 0.5, kPi)};
  const auto rows = parseLines(written(TrajectoryFormat::kKitti, {0, 1}, poses));
  ASSERT_EQ(rows.size(), 2u);
  ASSERT_EQ(rows[0].size(), 12u);
  // [R t] of a quarter turn about z at (2, 3, 0).
  const double quarter[12] = {0, -1, 0, 2, 1, 0, 0, 3, 0, 0, 1, 0};
  const double half[12] = {-1, 0, 0, -1, 0, -1, 0, 0.5, 0, 0, 1, 0};
  for (int k = 0; k < 12; ++k) {
    EXPECT_NEAR(rows[0][k], quarter[k], 1e-15) << k;
    EXPECT_NEAR(rows[1][k], half[k], 1e-15) << k;
  }
}

TEST(TrajectoryWriter, Kitti3DOnKnownRotations) {
  // A quarter turn about x, then about y.
  const SE3 rx(Eigen::Quaterniond(Eigen::AngleAxisd(kPi / 2, Eigen::Vector3d::UnitX())),
               Eigen::Vector3d(1, 2, 3));
  const SE3 ry(Eigen::Quaterniond(Eigen::AngleAxisd(kPi / 2, Eigen::Vector3d::UnitY())),
               Eigen::Vector3d(-4, 5, -6));
  const auto rows = parseLines(written(TrajectoryFormat::kKitti, {7, 8}, std::vector<SE3>{rx, ry}));
  ASSERT_EQ(rows.size(), 2u);
  const double about_x[12] = {1, 0, 0, 1, 0, 0, -1, 2, 0, 1, 0, 3};
  const double about_y[12] = {0, 0, 1, -4, 0, 1, 0, 5, -1, 0, 0, -6};
  for (int k = 0; k < 12; ++k) {
    EXPECT_NEAR(rows[0][k], about_x[k], 1e-15) << k;
    EXPECT_NEAR(rows[1][k], about_y[k], 1e-15) << k;
  }
}

TEST(TrajectoryWriter, RoundTrips3DExactlyInIdOrder) {
  std::mt19937_64 rng(9);
  std::vector<SE3> poses;
  const std::vector<Key> ids = {42, 5, 17, 1000000007, 0};
  for (size_t k = 0; k < ids.size(); ++k)
    poses.push_back(SE3::Exp(testing::randomTangent<SE3>(rng, 10.0, 2.0)));
  const std::vector<size_t> by_id = {4, 1, 2, 0, 3};
  const auto tum = parseLines(written(TrajectoryFormat::kTum, ids, poses));
  const auto kitti = parseLines(written(TrajectoryFormat::kKitti, ids, poses));
  ASSERT_EQ(tum.size(), ids.size());
  ASSERT_EQ(kitti.size(), ids.size());
  for (size_t k = 0; k < by_id.size(); ++k) {
    const SE3& x = poses[by_id[k]];
    EXPECT_EQ(tum[k][0], static_cast<double>(ids[by_id[k]]));
    for (int r = 0; r < 3; ++r) EXPECT_EQ(tum[k][1 + r], x.translation()(r));  // bit for bit
    EXPECT_EQ(tum[k][4], x.quaternion().x());
    EXPECT_EQ(tum[k][5], x.quaternion().y());
    EXPECT_EQ(tum[k][6], x.quaternion().z());
    EXPECT_EQ(tum[k][7], x.quaternion().w());
    Eigen::Matrix3d R;
    for (int r = 0; r < 3; ++r) {
      for (int c = 0; c < 3; ++c) R(r, c) = kitti[k][4 * r + c];
      EXPECT_EQ(kitti[k][4 * r + 3], x.translation()(r));
    }
    EXPECT_LT((R - x.rotation()).norm(), 1e-15);
    EXPECT_LT((R.transpose() * R - Eigen::Matrix3d::Identity()).norm(), 1e-14);
    EXPECT_NEAR(R.determinant(), 1.0, 1e-14);
  }
}

TEST(TrajectoryWriter, FormatsByName) {
  for (const char* name : {"g2o", "tum", "kitti"})
    EXPECT_STREQ(toString(parseTrajectoryFormat(name)), name);
  try {
    parseTrajectoryFormat("csv");
    FAIL();
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("'csv'"), std::string::npos) << e.what();
  }
}

TEST(TrajectoryWriter, BadInputIsRefused) {
  std::ostringstream out;
  const std::vector<SE2> two = {SE2(), SE2(1, 0, 0)};
  EXPECT_THROW(writeTrajectory(out, TrajectoryFormat::kTum, {1}, two), std::invalid_argument);
  EXPECT_THROW(writeTrajectory(out, TrajectoryFormat::kTum, {1, 1}, two), std::invalid_argument);
  EXPECT_THROW(writeTrajectory(out, TrajectoryFormat::kG2o, {1, 2}, two), std::invalid_argument);
  const std::vector<SE2> bad = {SE2(), SE2(std::nan(""), 0, 0)};
  try {
    writeTrajectory(out, TrajectoryFormat::kKitti, {3, 4}, bad);
    FAIL();
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("pose id 4"), std::string::npos) << e.what();
  }
  EXPECT_TRUE(out.str().empty());  // nothing written on a refusal
}

TEST(TrajectoryWriter, EstimateFilesByFormat) {
  PoseGraph2 graph;
  for (Key id : {3, 8}) {
    graph.index[id] = graph.numPoses();
    graph.ids.push_back(id);
    graph.poses.emplace_back();
  }
  graph.edges.push_back(
      RelativePoseEdge<SE2>::make(0, 1, SE2(1, 0, 0.1), RelativePoseEdge<SE2>::Matrix::Identity()));
  const std::vector<SE2> poses = {SE2(0, 0, 0), SE2(1.25, -0.5, 0.1)};
  const std::string base = ::testing::TempDir() + "arbor_trajectory_test";
  writeEstimateFile(base + ".tum", TrajectoryFormat::kTum, graph, poses);
  std::ifstream in(base + ".tum");
  const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  EXPECT_EQ(text, written(TrajectoryFormat::kTum, graph.ids, poses));
  writeEstimateFile(base + ".g2o", TrajectoryFormat::kG2o, graph, poses);
  const PoseGraph2 back = std::get<PoseGraph2>(readPoseGraphFile(base + ".g2o"));
  ASSERT_EQ(back.numPoses(), 2);
  EXPECT_EQ(back.poses[1].x(), 1.25);
  EXPECT_THROW(writeEstimateFile("/nonexistent/dir/x.tum", TrajectoryFormat::kTum, graph, poses),
               FileError);
  std::remove((base + ".tum").c_str());
  std::remove((base + ".g2o").c_str());
}

// With stamps, TUM's first field is the pose's time (ascending id order kept), written so that
// it reads back exactly; a pose without a stamp is refused naming its id. KITTI has no time.
TEST(TrajectoryWriter, TumTimesFromStamps) {
  std::mt19937 rng(5);
  std::vector<Key> ids = {7, 2, 40};
  std::vector<SE3> poses;
  for (size_t k = 0; k < ids.size(); ++k)
    poses.push_back(SE3::Exp(testing::isotropicNoise<SE3>(rng, 1.0)));
  const PoseStamps stamps = {{2, 1305031102.175304}, {7, 1305031102.211214}, {40, 0.5}};
  std::ostringstream out;
  writeTrajectory(out, TrajectoryFormat::kTum, ids, poses, &stamps);
  const auto rows = parseLines(out.str());
  ASSERT_EQ(rows.size(), 3u);
  EXPECT_EQ(rows[0][0], stamps.at(2));
  EXPECT_EQ(rows[1][0], stamps.at(7));
  EXPECT_EQ(rows[2][0], stamps.at(40));
  EXPECT_EQ(rows[1][1], poses[0].translation().x());
  std::ostringstream unstamped;
  writeTrajectory(unstamped, TrajectoryFormat::kTum, ids, poses);
  EXPECT_EQ(parseLines(unstamped.str())[2][0], 40.0);
  std::ostringstream kitti_stamped, kitti;
  writeTrajectory(kitti_stamped, TrajectoryFormat::kKitti, ids, poses, &stamps);
  writeTrajectory(kitti, TrajectoryFormat::kKitti, ids, poses);
  EXPECT_EQ(kitti_stamped.str(), kitti.str());
  const PoseStamps missing = {{2, 1.0}, {40, 3.0}};
  std::ostringstream sink;
  try {
    writeTrajectory(sink, TrajectoryFormat::kTum, ids, poses, &missing);
    ADD_FAILURE() << "a pose without a stamp was written";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("pose id 7 has no stamp"), std::string::npos) << e.what();
  }
}

TEST(TrajectoryWriter, FormatOfAPathsExtension) {
  EXPECT_EQ(trajectoryFormatOfPath("a/b.tum"), TrajectoryFormat::kTum);
  EXPECT_EQ(trajectoryFormatOfPath("B.KITTI"), TrajectoryFormat::kKitti);
  EXPECT_EQ(trajectoryFormatOfPath("x.y/out.g2o"), TrajectoryFormat::kG2o);
  EXPECT_EQ(trajectoryFormatOfPath("out.txt"), std::nullopt);
  EXPECT_EQ(trajectoryFormatOfPath("dir.tum/out"), std::nullopt);
  EXPECT_EQ(trajectoryFormatOfPath("out"), std::nullopt);
}

// The stamps file: "ID TIME" a line, comments and blank lines skipped; every malformed line is
// refused naming the file, the line and the value.
TEST(StampsFile, ReadsIdsAndTimesAndNamesBadLines) {
  std::istringstream good("# id time\n0 1305031102.175304\n\n3 +2.5  # comment\n");
  const PoseStamps stamps = readStamps(good, "s.txt");
  ASSERT_EQ(stamps.size(), 2u);
  EXPECT_EQ(stamps.at(0), 1305031102.175304);
  EXPECT_EQ(stamps.at(3), 2.5);
  const std::vector<std::pair<std::string, std::string>> bad = {
      {"0 1\n1\n", "s.txt:2: expected 'ID TIME_SECONDS', found 1 fields"},
      {"-1 2\n", "s.txt:1: pose id '-1'"},
      {"0 nan\n", "s.txt:1: time 'nan'"},
      {"0 abc\n", "s.txt:1: time 'abc'"},
      {"0 1\n0 2\n", "s.txt:2: pose id 0 is given twice"},
  };
  for (const auto& [text, message] : bad) {
    std::istringstream in(text);
    try {
      readStamps(in, "s.txt");
      ADD_FAILURE() << "accepted: " << text;
    } catch (const FileError& e) {
      EXPECT_EQ(std::string(e.what()).rfind(message, 0), 0u) << e.what();
    }
  }
  EXPECT_THROW(readStampsFile("/nonexistent/stamps.txt"), FileError);
}

}  // namespace
}  // namespace arbor
