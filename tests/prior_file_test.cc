// Priors in g2o files: EDGE_PRIOR_SE2, EDGE_PRIOR_SE2_XY, EDGE_SE3_PRIOR with its
// PARAMS_SE3OFFSET, EDGE_SE3_XYZ_PRIOR and our POSITION_PRIOR2 / POSITION_PRIOR3 — their exact
// values, the offset applied as g2o applies it (δ = z⁻¹ x o), every bad input refused naming
// its line, the information policies, and write → read round trips.
#include <cmath>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "arbor_slam/core/information.h"
#include "arbor_slam/io/pose_graph_file.h"
#include "arbor_slam/tests/pose_graph_file_support.h"

namespace arbor {
namespace {

using testing::kFileName;
using testing::num;
using testing::randomPose;
using testing::randomSpd;
using testing::readAs;
using testing::readError;

// The upper triangle of Ω row by row, each entry preceded by a space (g2o's order).
template <class Matrix>
std::string upperTriangle(const Matrix& omega) {
  std::string out;
  for (int r = 0; r < omega.rows(); ++r) {
    for (int c = r; c < omega.cols(); ++c) out += " " + num(omega(r, c));
  }
  return out;
}

std::string poseFields(const SE2& x) {
  return num(x.x()) + " " + num(x.y()) + " " + num(x.angle());
}

std::string poseFields(const SE3& x) {
  const Eigen::Quaterniond& q = x.quaternion();
  return num(x.translation().x()) + " " + num(x.translation().y()) + " " +
         num(x.translation().z()) + " " + num(q.x()) + " " + num(q.y()) + " " + num(q.z()) + " " +
         num(q.w());
}

const std::string kVertices2 = "VERTEX_SE2 3 0 0 0\nVERTEX_SE2 5 1 0 0\n";  // lines 1–2
const std::string kVertices3 = "VERTEX_SE3:QUAT 3 0 0 0 0 0 0 1\nVERTEX_SE3:QUAT 5 1 0 0 0 0 0 1\n";
const std::string kInfo2 = " 1 0 0 1 0 1";
const std::string kInfo3 = " 1 0 0 0 0 0 1 0 0 0 0 1 0 0 0 1 0 0 1 0 1";
const std::string kIdentityParams = "PARAMS_SE3OFFSET 0 0 0 0 0 0 0 1\n";

// ---------------------------------------------------------------------------------------------
// Each tag's values.

TEST(PriorFile, ReadsEdgePriorSe2WithItsValuesAndG2oInformationOrder) {
  ReadReport report;
  const auto graph = readAs<SE2>(kVertices2 + "EDGE_SE2 3 5 1 0 0" + kInfo2 +
                                     "\n"
                                     "EDGE_PRIOR_SE2 5 1.5 -2.25 0.75 11 12 13 22 23 33\n",
                                 {}, &report);
  ASSERT_EQ(graph.pose_priors.size(), 1u);
  EXPECT_TRUE(graph.position_priors.empty());
  const auto& p = graph.pose_priors[0];
  EXPECT_EQ(p.i, 1);  // id 5 is the second pose
  EXPECT_EQ(p.measurement.x(), 1.5);
  EXPECT_EQ(p.measurement.y(), -2.25);
  EXPECT_NEAR(p.measurement.angle(), 0.75, 1e-15);
  Eigen::Matrix3d expected;
  expected << 11, 12, 13, 12, 22, 23, 13, 23, 33;
  EXPECT_EQ(p.information, expected);
  EXPECT_FALSE(p.has_offset);
  EXPECT_EQ(report.pose_prior_lines, std::vector<int>{4});
  EXPECT_EQ(report.edge_lines, std::vector<int>{3});
  EXPECT_TRUE(graph.gaugeIndices().empty());  // the prior anchors the one component
}

TEST(PriorFile, G2oXyPriorAndOurPositionPrior2ReadTheSame) {
  ReadReport report;
  const auto graph = readAs<SE2>(kVertices2 +
                                     "EDGE_PRIOR_SE2_XY 3 4.5 -1.25 2 0.5 3\n"
                                     "POSITION_PRIOR2 3 4.5 -1.25 2 0.5 3\n",
                                 {}, &report);
  ASSERT_EQ(graph.position_priors.size(), 2u);
  Eigen::Matrix2d expected;
  expected << 2, 0.5, 0.5, 3;
  for (const auto& p : graph.position_priors) {
    EXPECT_EQ(p.i, 0);
    EXPECT_EQ(p.position, Eigen::Vector2d(4.5, -1.25));
    EXPECT_EQ(p.information, expected);
  }
  EXPECT_EQ(report.position_prior_lines, (std::vector<int>{3, 4}));
  // Cost (t − p)ᵀΩ(t − p) at a pose, by hand.
  const SE2 x(4.0, -1.0, 0.3);
  const Eigen::Vector2d e(4.0 - 4.5, -1.0 + 1.25);
  EXPECT_NEAR(graph.position_priors[0].cost(x), e.dot(expected * e), 1e-14);
}

TEST(PriorFile, Se2PriorCostIsTheHandComputedOne) {
  // δ = z⁻¹ x: t(δ) = R(−θz)(t(x) − t(z)), θ(δ) = θx − θz (wrapped); cost eᵀΩe.
  std::mt19937_64 rng(21);
  const Eigen::Matrix3d omega = randomSpd<3>(rng);
  const SE2 z(1.5, -0.5, 2.9);
  const auto graph =
      readAs<SE2>(kVertices2 + "EDGE_PRIOR_SE2 3 " + poseFields(z) + upperTriangle(omega) + "\n");
  const SE2 x(0.25, 2.0, -3.0);
  const double c = std::cos(z.angle()), s = std::sin(z.angle());
  const Eigen::Vector2d d(x.x() - z.x(), x.y() - z.y());
  double theta = -3.0 - z.angle();
  theta = std::atan2(std::sin(theta), std::cos(theta));
  const Eigen::Vector3d e(c * d.x() + s * d.y(), -s * d.x() + c * d.y(), theta);
  EXPECT_NEAR(graph.pose_priors[0].cost(x), e.dot(omega * e), 1e-12 * e.dot(omega * e));
}

// e = [t(δ); 2·vec q(δ)], q_w ≥ 0, with δ = z⁻¹ x o computed from quaternions by hand.
Eigen::Matrix<double, 6, 1> handError(const SE3& z, const SE3& x, const SE3& o) {
  const Eigen::Quaterniond qz = z.quaternion(), qx = x.quaternion(), qo = o.quaternion();
  const Eigen::Vector3d t_xo = qx * o.translation() + x.translation();  // t(x o)
  Eigen::Quaterniond q = qz.conjugate() * qx * qo;
  if (q.w() < 0) q.coeffs() = -q.coeffs();
  Eigen::Matrix<double, 6, 1> e;
  e << qz.conjugate() * (t_xo - z.translation()), 2.0 * q.vec();
  return e;
}

TEST(PriorFile, Se3PriorReadsItsValuesAndAppliesTheOffsetAsG2oDoes) {
  std::mt19937_64 rng(8);
  const Eigen::Matrix<double, 6, 6> omega = randomSpd<6>(rng);
  const SE3 z = randomPose<SE3>(rng, 1.0);
  const SE3 o = randomPose<SE3>(rng, 0.5);
  ReadReport report;
  const auto graph =
      readAs<SE3>(kVertices3 + "PARAMS_SE3OFFSET 7 " + poseFields(o) +
                      "\n"
                      "EDGE_SE3_PRIOR 5 7 " +
                      poseFields(z) + upperTriangle(omega) + "\n" + kIdentityParams +
                      "EDGE_SE3_PRIOR 3 0 " + poseFields(z) + upperTriangle(omega) + "\n",
                  {}, &report);
  ASSERT_EQ(graph.pose_priors.size(), 2u);
  EXPECT_EQ(report.pose_prior_lines, (std::vector<int>{4, 6}));
  const auto& p = graph.pose_priors[0];
  EXPECT_EQ(p.i, 1);
  EXPECT_EQ(p.information, omega);
  EXPECT_EQ(p.measurement.translation(), z.translation());
  EXPECT_LE((p.measurement.quaternion().coeffs() - z.quaternion().coeffs()).norm(), 1e-15);
  EXPECT_TRUE(p.has_offset);
  EXPECT_EQ(p.offset.translation(), o.translation());
  EXPECT_LE((p.offset.quaternion().coeffs() - o.quaternion().coeffs()).norm(), 1e-15);
  EXPECT_FALSE(graph.pose_priors[1].has_offset);  // parameter 0 is the identity here
  EXPECT_EQ(graph.pose_priors[1].i, 0);

  // The cost at a pose is eᵀΩe with δ = z⁻¹ x o; without the offset it would be another.
  const SE3 x = randomPose<SE3>(rng, 1.0);
  const Eigen::Matrix<double, 6, 1> e = handError(z, x, o);
  const double expected = e.dot(omega * e);
  EXPECT_NEAR(p.cost(x), expected, 1e-12 * expected);
  const Eigen::Matrix<double, 6, 1> e0 = handError(z, x, SE3::Identity());
  EXPECT_NEAR(graph.pose_priors[1].cost(x), e0.dot(omega * e0), 1e-12 * e0.dot(omega * e0));
  EXPECT_GT(std::abs(expected - e0.dot(omega * e0)), 1e-3 * expected);
}

TEST(PriorFile, Se3PositionPriorsG2oAndOurs) {
  std::mt19937_64 rng(4);
  const Eigen::Matrix3d omega = randomSpd<3>(rng);
  const std::string p = " 4.5 -1.25 0.5";
  ReadReport report;
  const auto graph = readAs<SE3>(kVertices3 + kIdentityParams + "EDGE_SE3_XYZ_PRIOR 5 0" + p +
                                     upperTriangle(omega) + "\nPOSITION_PRIOR3 5" + p +
                                     upperTriangle(omega) + "\n",
                                 {}, &report);
  ASSERT_EQ(graph.position_priors.size(), 2u);
  EXPECT_EQ(report.position_prior_lines, (std::vector<int>{4, 5}));
  EXPECT_TRUE(report.warnings.empty());
  const SE3 x = randomPose<SE3>(rng, 2.0);
  const Eigen::Vector3d e = x.translation() - Eigen::Vector3d(4.5, -1.25, 0.5);
  for (const auto& prior : graph.position_priors) {
    EXPECT_EQ(prior.i, 1);
    EXPECT_EQ(prior.position, Eigen::Vector3d(4.5, -1.25, 0.5));
    EXPECT_EQ(prior.information, omega);
    EXPECT_NEAR(prior.cost(x), e.dot(omega * e), 1e-12 * e.dot(omega * e));
  }
}

TEST(PriorFile, XyzPriorIgnoresANonIdentityOffsetWithAWarningAsG2oIgnoresIt) {
  ReadReport report;
  const auto graph = readAs<SE3>(kVertices3 +
                                     "PARAMS_SE3OFFSET 2 0.5 0 0 0 0 0 1\n"
                                     "EDGE_SE3_XYZ_PRIOR 3 2 1 2 3 1 0 0 1 0 1\n",
                                 {}, &report);
  ASSERT_EQ(graph.position_priors.size(), 1u);
  EXPECT_EQ(graph.position_priors[0].position, Eigen::Vector3d(1, 2, 3));
  EXPECT_EQ(graph.position_priors[0].cost(SE3::Identity()), 14.0);  // |0 − (1,2,3)|²
  ASSERT_EQ(report.warnings.size(), 1u);
  EXPECT_EQ(report.warnings[0].rfind("test.g2o:4: EDGE_SE3_XYZ_PRIOR's offset parameter 2 is "
                                     "not the identity",
                                     0),
            0u)
      << report.warnings[0];
}

TEST(PriorFile, ParamsMayFollowTheirPriorAndAreNormalised) {
  ReadReport report;
  const auto graph = readAs<SE3>(kVertices3 + "EDGE_SE3_PRIOR 3 4 0 0 0 0 0 0 1" + kInfo3 +
                                     "\nPARAMS_SE3OFFSET 4 1 2 3 0 0 0 2\n",
                                 {}, &report);
  ASSERT_EQ(graph.pose_priors.size(), 1u);
  EXPECT_EQ(graph.pose_priors[0].offset.translation(), Eigen::Vector3d(1, 2, 3));
  EXPECT_EQ(graph.pose_priors[0].offset.quaternion().w(), 1.0);
  ASSERT_EQ(report.warnings.size(), 1u);  // the quaternion of norm 2, as for a VERTEX
  EXPECT_EQ(report.warnings[0].rfind("test.g2o:4: quaternion norm 2", 0), 0u) << report.warnings[0];
}

TEST(PriorFile, InAnEdgesOnlyFileAPriorsIdIsAPose) {
  const auto graph = readAs<SE2>("EDGE_SE2 4 9 1 0 0" + kInfo2 +
                                 "\n"
                                 "EDGE_PRIOR_SE2 2 0 0 0" +
                                 kInfo2 +
                                 "\n"
                                 "POSITION_PRIOR2 12 1 1 1 0 1\n"
                                 "FIX 12\n");
  EXPECT_FALSE(graph.has_initial_estimate);
  EXPECT_EQ(graph.ids, (std::vector<Key>{2, 4, 9, 12}));
  EXPECT_EQ(graph.pose_priors[0].i, 0);
  EXPECT_EQ(graph.position_priors[0].i, 3);
  EXPECT_EQ(graph.fixed, std::vector<int>{3});
  EXPECT_EQ(graph.edges[0].i, 1);

  // A file of priors alone is a graph of the poses they name.
  const auto priors_only =
      readAs<SE3>(kIdentityParams + "EDGE_SE3_PRIOR 6 0 0 0 0 0 0 0 1" + kInfo3 + "\n");
  EXPECT_EQ(priors_only.ids, std::vector<Key>{6});
  EXPECT_EQ(priors_only.numEdges(), 0);
}

// ---------------------------------------------------------------------------------------------
// Bad input.

struct BadCase {
  std::string text;
  int line;
  std::string message;
};

TEST(PriorFile, BadPriorLinesNameTheLineAndTheValue) {
  const std::string p0 = kIdentityParams;  // line 3 after kVertices3
  const std::vector<BadCase> cases = {
      // Field counts.
      {kVertices2 + "EDGE_PRIOR_SE2 3 0 0 0 1 0 0 1 0\n", 3,
       "too few fields for EDGE_PRIOR_SE2: expected 10 after the tag (id x y theta + 6 "
       "information entries), found 9"},
      {kVertices2 + "EDGE_PRIOR_SE2_XY 3 0 0 1 0 1 9\n", 3,
       "too many fields for EDGE_PRIOR_SE2_XY: expected 6 after the tag (id x y + 3 information "
       "entries), found 7"},
      {kVertices2 + "POSITION_PRIOR2 3 0 0 1 0\n", 3, "too few fields for POSITION_PRIOR2"},
      {kVertices3 + p0 + "EDGE_SE3_PRIOR 3 0 0 0 0 0 0 1" + kInfo3 + "\n", 4,
       "too few fields for EDGE_SE3_PRIOR: expected 30 after the tag (id parameter-id x y z qx "
       "qy qz qw + 21 information entries), found 29"},
      {kVertices3 + p0 + "EDGE_SE3_XYZ_PRIOR 3 1 2 3 1 0 0 1 0 1\n", 4,
       "too few fields for EDGE_SE3_XYZ_PRIOR: expected 11"},
      {kVertices3 + "POSITION_PRIOR3 3 0 1 2 3 1 0 0 1 0 1\n", 3,
       "too many fields for POSITION_PRIOR3: expected 10"},
      {kVertices3 + "PARAMS_SE3OFFSET 0 0 0 0 0 0 1\n", 3,
       "too few fields for PARAMS_SE3OFFSET: expected 8 after the tag (parameter-id x y z qx qy "
       "qz qw)"},
      // Values.
      {kVertices2 + "EDGE_PRIOR_SE2 3 0 nan 0" + kInfo2 + "\n", 3,
       "field 4 of EDGE_PRIOR_SE2 ('nan') is not finite"},
      {kVertices2 + "EDGE_PRIOR_SE2 3 0 0 0 1 0 0 inf 0 1\n", 3,
       "field 9 of EDGE_PRIOR_SE2 ('inf') is not finite"},
      {kVertices2 + "POSITION_PRIOR2 3 1e999 0 1 0 1\n", 3, "('1e999') is out of the range"},
      {kVertices2 + "EDGE_PRIOR_SE2_XY -3 0 0 1 0 1\n", 3, "('-3') is a negative id"},
      {kVertices3 + "EDGE_SE3_PRIOR 3 x 0 0 0 0 0 0 1" + kInfo3 + "\n", 3,
       "field 3 of EDGE_SE3_PRIOR ('x') is not a non-negative integer id"},
      {kVertices3 + p0 + "EDGE_SE3_PRIOR 3 0 0 0 0 0 0 0 0" + kInfo3 + "\n", 4,
       "quaternion (qx qy qz qw) = (0 0 0 0) is zero"},
      {kVertices3 + "PARAMS_SE3OFFSET 0 0 0 0 0 0 0 0\n", 3, "is zero"},
      {kVertices3 + "PARAMS_SE3OFFSET 0 -2e15 0 0 0 0 0 1\n", 3,
       "translation component of magnitude 2e+15 beyond the largest accepted (1e+15)"},
      // Magnitudes beyond what F = Σ eᵀΩe can hold.
      {kVertices2 + "EDGE_PRIOR_SE2 3 1e16 0 0" + kInfo2 + "\n", 3,
       "translation component of magnitude 1e+16 beyond the largest accepted"},
      {kVertices2 + "POSITION_PRIOR2 3 0 -1e308 1 0 1\n", 3, "position component of magnitude"},
      {kVertices3 + "POSITION_PRIOR3 3 0 0 0 1e31 0 0 1 0 1\n", 3,
       "information matrix has an entry of magnitude 1e+31, beyond the largest accepted"},
      {kVertices3 + p0 + "EDGE_SE3_PRIOR 3 0 0 0 0 0 0 0 1 -1e308" + kInfo3.substr(2) + "\n", 4,
       "information matrix has an entry of magnitude 1e+308"},
      // Ids and parameters.
      {kVertices2 + "EDGE_PRIOR_SE2 7 0 0 0" + kInfo2 + "\n", 3,
       "EDGE_PRIOR_SE2 on id 7, which has no VERTEX"},
      {kVertices3 + "POSITION_PRIOR3 4 0 0 0 1 0 0 1 0 1\n", 3,
       "POSITION_PRIOR3 on id 4, which has no VERTEX"},
      {kVertices3 + p0 + "EDGE_SE3_PRIOR 3 2 0 0 0 0 0 0 1" + kInfo3 + "\n", 4,
       "EDGE_SE3_PRIOR names offset parameter 2, which no PARAMS_SE3OFFSET line defines"},
      {kVertices3 + "EDGE_SE3_PRIOR 3 0 0 0 0 0 0 0 1" + kInfo3 + "\n", 3,
       "EDGE_SE3_PRIOR names offset parameter 0, which no PARAMS_SE3OFFSET line defines (g2o "
       "has no default offset)"},
      {kVertices3 + "EDGE_SE3_XYZ_PRIOR 3 0 0 0 0 1 0 0 1 0 1\n", 3,
       "EDGE_SE3_XYZ_PRIOR names offset parameter 0, which no PARAMS_SE3OFFSET"},
      {kVertices3 + p0 + "PARAMS_SE3OFFSET 0 1 0 0 0 0 0 1\n", 4,
       "duplicate PARAMS_SE3OFFSET id 0 (first at line 3)"},
      {kVertices3 + "PARAMS_SE3OFFSET -1 0 0 0 0 0 0 1\n", 3, "('-1') is a negative id"},
      // Tags.
      {kVertices2 + "PARAMS_SE3OFFSET 0 0 0 0 0 0 0 1\n", 3,
       "mixes 2D and 3D records: PARAMS_SE3OFFSET after VERTEX_SE2 at line 1"},
      {kVertices3 + "EDGE_PRIOR_SE2 3 0 0 0" + kInfo2 + "\n", 3,
       "mixes 2D and 3D records: EDGE_PRIOR_SE2 after VERTEX_SE3:QUAT"},
      {kVertices2 + "EDGE_SE2_PRIOR 3 0 0 0" + kInfo2 + "\n", 3,
       "unknown tag 'EDGE_SE2_PRIOR' (g2o's tag is EDGE_PRIOR_SE2)"},
      {kVertices3 + "EDGE_SE3_XYZPRIOR 3 0 0 0 0 1 0 0 1 0 1\n", 3,
       "unknown tag 'EDGE_SE3_XYZPRIOR' (g2o's tag is EDGE_SE3_XYZ_PRIOR)"},
      {kVertices2 + "PARAMS_SE2OFFSET 0 0 0 0\n", 3, "unknown tag 'PARAMS_SE2OFFSET'"},
      {kVertices2 + "POSITION_PRIOR 3 0 0 1 0 1\n", 3, "unknown tag 'POSITION_PRIOR'"},
  };
  for (const auto& c : cases) {
    const std::string message = readError(c.text);
    const std::string where = std::string(kFileName) + ":" + std::to_string(c.line) + ": ";
    EXPECT_EQ(message.rfind(where, 0), 0u) << "input:\n" << c.text << "message: " << message;
    EXPECT_NE(message.find(c.message), std::string::npos)
        << "input:\n"
        << c.text << "message: " << message << "\nwanted: " << c.message;
  }
}

TEST(PriorFile, ParametersAloneAreNoGraph) {
  EXPECT_EQ(readError(kIdentityParams), "test.g2o: no VERTEX or EDGE records");
}

// ---------------------------------------------------------------------------------------------
// Information policies: an edge and two priors with indefinite Ω (lines 3, 5 and 6).

const std::string kIndefinitePriors =
    kVertices2 +
    "EDGE_SE2 3 5 1 0 0 1 2 0 1 0 1\n"  // eigenvalues −1, 1, 3
    "EDGE_PRIOR_SE2 3 0 0 0 4 0 0 4 0 1\n"
    "EDGE_PRIOR_SE2 5 1 0 0 1 0 0 1 0 -2\n"  // eigenvalues 1, 1, −2
    "POSITION_PRIOR2 5 1 0 1 3 1\n"          // eigenvalues −2, 4
    "POSITION_PRIOR2 3 0 0 1 0 4\n";

TEST(PriorFile, IndefinitePriorInformationIsRefusedWithTheEdgesInOneError) {
  EXPECT_EQ(readError(kIndefinitePriors),
            "test.g2o: 3 of 5 edges and priors have an information matrix that is not positive "
            "definite; first at lines 3, 5, 6; use --information repair or isotropic");
}

TEST(PriorFile, RepairReplacesOnlyTheIndefinitePriorInformation) {
  ReadReport report;
  const auto graph = readAs<SE2>(kIndefinitePriors, {InformationPolicy::kRepair}, &report);
  EXPECT_EQ(report.repaired, 3);
  EXPECT_EQ(report.made_isotropic, 0);
  Eigen::Matrix3d bad;
  bad << 1, 0, 0, 0, 1, 0, 0, 0, -2;
  EXPECT_EQ(graph.pose_priors[0].information,
            Eigen::Vector3d(4, 4, 1).asDiagonal().toDenseMatrix());
  EXPECT_TRUE(graph.pose_priors[1].information.isApprox(nearestPositiveDefinite(bad), 1e-12));
  Eigen::Matrix2d bad_position;
  bad_position << 1, 3, 3, 1;
  EXPECT_TRUE(
      graph.position_priors[0].information.isApprox(nearestPositiveDefinite(bad_position), 1e-12));
  EXPECT_EQ(graph.position_priors[1].information,
            Eigen::Vector2d(1, 4).asDiagonal().toDenseMatrix());
}

TEST(PriorFile, IsotropicMakesAPositionPriorTauTimesIdentity) {
  ReadReport report;
  const auto graph = readAs<SE2>(kIndefinitePriors, {InformationPolicy::kIsotropic}, &report);
  EXPECT_EQ(report.made_isotropic, 5);
  EXPECT_EQ(report.repaired, 3);
  // Ω = diag(1, 4): τ = d / tr(Ω⁻¹) = 2 / (1 + 1/4) = 1.6.
  const Eigen::Matrix2d& omega = graph.position_priors[1].information;
  EXPECT_NEAR(omega(0, 0), 1.6, 1e-15);
  EXPECT_NEAR(omega(1, 1), 1.6, 1e-15);
  EXPECT_EQ(omega(0, 1), 0.0);
  // A pose prior takes the edges' isotropic form: Ω = diag(4, 4, 1) is already isotropic.
  EXPECT_TRUE(graph.pose_priors[0].information.isApprox(
      isotropicInformation(Eigen::Vector3d(4, 4, 1).asDiagonal().toDenseMatrix(), 2), 1e-15));
  const Eigen::Matrix3d& repaired = graph.pose_priors[1].information;
  EXPECT_EQ(repaired(0, 0), repaired(1, 1));
  EXPECT_GT(repaired(2, 2), 0.0);
}

// ---------------------------------------------------------------------------------------------
// Writing.

template <class G>
PoseGraph<G> graphWithPriors(std::mt19937_64& rng) {
  PoseGraph<G> graph;
  for (int k = 0; k < 6; ++k) {
    const Key id = 10 + 3 * k;
    graph.ids.push_back(id);
    graph.index[id] = k;
    graph.poses.push_back(randomPose<G>(rng, 2.0));
  }
  for (int k = 0; k + 1 < 6; ++k) {
    graph.edges.push_back(
        RelativePoseEdge<G>::make(k, k + 1, randomPose<G>(rng, 1.0), randomSpd<G::kDoF>(rng)));
  }
  const G shared_offset = randomPose<G>(rng, 0.5);
  const std::vector<G> offsets = {G::Identity(), shared_offset, randomPose<G>(rng, 0.5),
                                  shared_offset};
  for (int k = 0; k < 4; ++k) {
    // 2D pose priors have no offset in g2o (EdgeSE2Prior); 3D ones take one per prior.
    const G offset = G::kDim == 3 ? offsets[k] : G::Identity();
    graph.pose_priors.push_back(
        PosePriorFactor<G>::make(k + 1, randomPose<G>(rng, 1.0), randomSpd<G::kDoF>(rng), offset));
  }
  for (int k = 0; k < 3; ++k) {
    const typename G::Translation p = randomPose<G>(rng, 3.0).translation();
    graph.position_priors.push_back(
        PositionPriorFactor<G>::make(5 - k, p, randomSpd<G::kDim>(rng)));
  }
  graph.has_initial_estimate = true;
  return graph;
}

template <class G>
class PriorRoundTripTest : public ::testing::Test {};
using Groups = ::testing::Types<SE2, SE3>;
TYPED_TEST_SUITE(PriorRoundTripTest, Groups);

TYPED_TEST(PriorRoundTripTest, PriorsAndOffsetsReadBack) {
  using G = TypeParam;
  std::mt19937_64 rng(31);
  const PoseGraph<G> graph = graphWithPriors<G>(rng);
  std::ostringstream out;
  writeG2o(out, graph, graph.poses);
  const std::string text = out.str();
  ReadReport report;
  const PoseGraph<G> back = readAs<G>(text, {}, &report);
  EXPECT_TRUE(report.warnings.empty());
  ASSERT_EQ(back.pose_priors.size(), graph.pose_priors.size());
  ASSERT_EQ(back.position_priors.size(), graph.position_priors.size());
  EXPECT_EQ(back.numEdges(), graph.numEdges());
  for (std::size_t k = 0; k < graph.pose_priors.size(); ++k) {
    const auto& a = graph.pose_priors[k];
    const auto& b = back.pose_priors[k];
    EXPECT_EQ(a.i, b.i);
    EXPECT_LE(a.measurement.localCoordinates(b.measurement).norm(), 1e-12) << k;
    EXPECT_LE((a.information - b.information).cwiseAbs().maxCoeff(), 1e-12) << k;
    EXPECT_EQ(a.has_offset, b.has_offset) << k;
    EXPECT_LE(a.offset.localCoordinates(b.offset).norm(), 1e-12) << k;
    const G x = randomPose<G>(rng, 2.0);
    EXPECT_NEAR(a.cost(x), b.cost(x), 1e-12 * a.cost(x)) << k;
  }
  for (std::size_t k = 0; k < graph.position_priors.size(); ++k) {
    const auto& a = graph.position_priors[k];
    const auto& b = back.position_priors[k];
    EXPECT_EQ(a.i, b.i);
    EXPECT_LE((a.position - b.position).cwiseAbs().maxCoeff(), 1e-12) << k;
    EXPECT_LE((a.information - b.information).cwiseAbs().maxCoeff(), 1e-12) << k;
  }
}

TEST(PriorFile, WrittenSe3PriorsNameTheirParametersWhichComeFirst) {
  std::mt19937_64 rng(2);
  const PoseGraph3 graph = graphWithPriors<SE3>(rng);
  std::ostringstream out;
  writeG2o(out, graph, graph.poses);
  std::istringstream in(out.str());
  std::vector<std::string> params, pose_priors, position_priors;
  bool prior_seen = false, params_after_prior = false;
  for (std::string line; std::getline(in, line);) {
    const std::string tag = line.substr(0, line.find(' '));
    if (tag == "PARAMS_SE3OFFSET") {
      params.push_back(line);
      params_after_prior = params_after_prior || prior_seen;
    }
    if (tag == "EDGE_SE3_PRIOR") pose_priors.push_back(line);
    if (tag == "EDGE_SE3_XYZ_PRIOR") position_priors.push_back(line);
    prior_seen = prior_seen || tag == "EDGE_SE3_PRIOR" || tag == "EDGE_SE3_XYZ_PRIOR";
  }
  EXPECT_FALSE(params_after_prior);  // g2o needs a parameter before its first use
  // Identity, the shared offset, the third: three parameters for four priors.
  ASSERT_EQ(params.size(), 3u);
  EXPECT_EQ(params[0], "PARAMS_SE3OFFSET 0 0 0 0 0 0 0 1");
  ASSERT_EQ(pose_priors.size(), 4u);
  const auto parameterOf = [](const std::string& line) {
    std::istringstream fields(line);
    std::string tag, id, parameter;
    fields >> tag >> id >> parameter;
    return parameter;
  };
  EXPECT_EQ(parameterOf(pose_priors[0]), "0");
  EXPECT_EQ(parameterOf(pose_priors[1]), "1");
  EXPECT_EQ(parameterOf(pose_priors[2]), "2");
  EXPECT_EQ(parameterOf(pose_priors[3]), "1");
  ASSERT_EQ(position_priors.size(), 3u);
  for (const auto& line : position_priors) EXPECT_EQ(parameterOf(line), "0");
}

TEST(PriorFile, WriterOutputWithoutPriorsIsUnchanged) {
  PoseGraph2 graph;
  graph.ids = {4, 7};
  graph.index = {{4, 0}, {7, 1}};
  graph.poses = {SE2(0, 0, 0), SE2(1.5, -2, 0.5)};
  graph.edges.push_back(
      RelativePoseEdge<SE2>::make(0, 1, SE2(1, 0.25, 0), Eigen::Matrix3d::Identity() * 2));
  graph.fixed = {0};
  std::ostringstream out;
  writeG2o(out, graph, graph.poses);
  EXPECT_EQ(out.str(),
            "VERTEX_SE2 4 0 0 0\n"
            "VERTEX_SE2 7 1.5 -2 0.5\n"
            "FIX 4\n"
            "EDGE_SE2 4 7 1 0.25 0 2 0 0 2 0 2\n");
  graph.position_priors.push_back(
      PositionPriorFactor<SE2>::make(1, Eigen::Vector2d(3, -1), Eigen::Matrix2d::Identity()));
  std::ostringstream with_prior;
  writeG2o(with_prior, graph, graph.poses);
  EXPECT_EQ(with_prior.str(), out.str() + "EDGE_PRIOR_SE2_XY 7 3 -1 1 0 1\n");
}

TEST(PriorFile, WriterRefusesAPriorOutOfRangeOrNotFinite) {
  std::mt19937_64 rng(6);
  PoseGraph3 graph = graphWithPriors<SE3>(rng);
  std::ostringstream out;
  PoseGraph3 bad = graph;
  bad.pose_priors[0].i = graph.numPoses();
  EXPECT_THROW(writeG2o(out, bad, bad.poses), std::invalid_argument);
  bad = graph;
  bad.position_priors[1].position.x() = std::nan("");
  EXPECT_THROW(writeG2o(out, bad, bad.poses), std::invalid_argument);
  bad = graph;
  bad.pose_priors[2].information(0, 0) = INFINITY;
  EXPECT_THROW(writeG2o(out, bad, bad.poses), std::invalid_argument);

  // g2o's 2D pose prior has no offset: one with an offset is refused rather than dropped.
  PoseGraph2 planar = graphWithPriors<SE2>(rng);
  planar.pose_priors[0] =
      PosePriorFactor<SE2>::make(0, SE2(1, 2, 0.5), Eigen::Matrix3d::Identity(), SE2(0.5, 0, 0));
  EXPECT_THROW(writeG2o(out, planar, planar.poses), std::invalid_argument);
}

}  // namespace
}  // namespace arbor
