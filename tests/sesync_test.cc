// SE-Sync (core/sesync_problem.h, core/riemannian_staircase.h): the data matrices against a
// direct evaluation, certified global optima on shared datasets and synthetic graphs, a case
// where LM from odometry stalls, the certificate at optimal and perturbed points, bad input.
#include <cmath>
#include <iostream>
#include <random>
#include <stdexcept>
#include <string>

#include <gtest/gtest.h>
#include <Eigen/Dense>

#include "arbor_slam/core/batch_solver.h"
#include "arbor_slam/core/initialization.h"
#include "arbor_slam/core/prior_factors.h"
#include "arbor_slam/core/riemannian_staircase.h"
#include "arbor_slam/core/sesync_problem.h"
#include "arbor_slam/io/pose_graph_file.h"
#include "arbor_slam/tests/random_graphs.h"
#include "shared_data.h"

namespace arbor {
namespace {

using testing::randomInformation;
using testing::randomTangent;
using testing::Synthetic;

template <class G>
void addEdge(Synthetic<G>* s, int i, int j, const typename G::Tangent& noise,
             const typename RelativePoseEdge<G>::Matrix& omega) {
  const G z = s->truth[i].between(s->truth[j]).compose(G::Exp(noise));
  s->graph.edges.push_back(RelativePoseEdge<G>::make(i, j, z, omega));
}

template <class G>
void setIds(Synthetic<G>* s) {
  auto& g = s->graph;
  for (int k = 0; k < static_cast<int>(s->truth.size()); ++k) {
    g.ids.push_back(10 + k);
    g.index[10 + k] = k;
  }
  g.poses = s->truth;
  g.has_initial_estimate = false;
}

// A random walk with odometry and random loop closures (translation noise σ_t, rotation σ_r).
template <class G>
Synthetic<G> randomGraph(int n, int loops, double sigma_t, double sigma_r, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  Synthetic<G> s;
  s.truth.push_back(G::Identity());
  for (int k = 1; k < n; ++k) {
    typename G::Tangent step = randomTangent<G>(rng, 0.5, 0.3);
    step(0) += 1.0;
    s.truth.push_back(s.truth.back().compose(G::Exp(step)));
  }
  setIds(&s);
  for (int k = 0; k + 1 < n; ++k) {
    addEdge(&s, k, k + 1, randomTangent<G>(rng, sigma_t, sigma_r), randomInformation<G>(rng));
  }
  std::uniform_int_distribution<int> pick(0, n - 1);
  for (int l = 0; l < loops;) {
    const int i = pick(rng), j = pick(rng);
    if (std::abs(i - j) < 2) continue;
    addEdge(&s, i, j, randomTangent<G>(rng, sigma_t, sigma_r), randomInformation<G>(rng));
    ++l;
  }
  return s;
}

// A planar ring of n poses facing along it, odometry with large rotation noise and chords to
// the opposite side with accurate measurements: its odometry start is far from the optimum.
Synthetic<SE2> noisyRing(int n, double sigma_r, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  Synthetic<SE2> s;
  const double radius = 10.0;
  for (int k = 0; k < n; ++k) {
    const double a = 2 * M_PI * k / n;
    s.truth.emplace_back(radius * std::cos(a), radius * std::sin(a), a + M_PI / 2);
  }
  setIds(&s);
  Eigen::Matrix3d odo = Eigen::Vector3d(100, 100, 1.0 / (sigma_r * sigma_r)).asDiagonal();
  Eigen::Matrix3d chord = Eigen::Vector3d(100, 100, 1e4).asDiagonal();
  for (int k = 0; k < n; ++k) {
    addEdge(&s, k, (k + 1) % n, randomTangent<SE2>(rng, 0.1, sigma_r), odo);
  }
  for (int k = 0; k < n / 2; k += 10) {
    addEdge(&s, k, k + n / 2, randomTangent<SE2>(rng, 0.1, 0.01), chord);
  }
  return s;
}

// SE-Sync's cost Σ κ‖Rⱼ − Rᵢ R̃‖²_F + τ‖tⱼ − tᵢ − Rᵢ t̃‖², evaluated directly.
double sesyncCost(const std::vector<SESyncMeasurement>& ms, const Eigen::MatrixXd& R,
                  const Eigen::MatrixXd& T, int d) {
  double f = 0;
  for (const auto& m : ms) {
    const Eigen::MatrixXd Ri = R.middleRows(d * m.i, d).transpose();
    const Eigen::MatrixXd Rj = R.middleRows(d * m.j, d).transpose();
    const Eigen::VectorXd ti = T.row(m.i).transpose(), tj = T.row(m.j).transpose();
    f += m.kappa * (Rj - Ri * m.R).squaredNorm() + m.tau * (tj - ti - Ri * m.t).squaredNorm();
  }
  return f;
}

template <class G>
void checkDataMatrices(std::uint64_t seed) {
  constexpr int d = G::kDim;
  const Synthetic<G> s = randomGraph<G>(30, 20, 0.1, 0.05, seed);
  const auto ms = sesyncMeasurements(s.graph);
  const SESyncProblem problem(30, d, ms);
  Eigen::MatrixXd R(d * 30, d);
  for (int i = 0; i < 30; ++i) R.middleRows(d * i, d) = s.truth[i].rotation().transpose();
  const Eigen::MatrixXd T = problem.recoverTranslations(R);
  const double f = sesyncCost(ms, R, T, d);
  EXPECT_NEAR(problem.objective(R), f, 1e-9 * f);
  // The recovered translations minimise the cost: any perturbation raises it.
  std::mt19937_64 rng(seed + 1);
  std::normal_distribution<double> noise(0, 0.05);
  Eigen::MatrixXd T2 = T;
  for (int k = 0; k < T2.size(); ++k) T2.data()[k] += noise(rng);
  EXPECT_GT(sesyncCost(ms, R, T2, d), f);
  // The isotropic weights, as SE-Sync's reader: with ω = isotropicInformation's rotational
  // precision, κ = ω in 2D (Ω_θθ) and ω/2 = 3 / (2 tr(Ω_rr⁻¹)) in 3D.
  const Eigen::MatrixXd iso = isotropicInformation(s.graph.edges[0].information, d);
  EXPECT_DOUBLE_EQ(ms[0].tau, iso(0, 0));
  EXPECT_DOUBLE_EQ(ms[0].kappa, d == 2 ? iso(d, d) : 0.5 * iso(d, d));
}

TEST(SESyncProblem, QuadraticFormMatchesDirectCost2D) { checkDataMatrices<SE2>(3); }
TEST(SESyncProblem, QuadraticFormMatchesDirectCost3D) { checkDataMatrices<SE3>(4); }

// SE-Sync's model has relative-pose edges only: a graph with priors is refused with a message
// that sends it to the batch solvers, which take every factor; without the priors it solves.
template <class G>
void checkPriorsRefused() {
  Synthetic<G> s = randomGraph<G>(8, 3, 0.0, 0.0, 7);
  const auto omega = RelativePoseEdge<G>::Matrix::Identity();
  const auto omega_t = PositionPriorFactor<G>::Matrix::Identity();
  s.graph.pose_priors.push_back(PosePriorFactor<G>::make(2, s.truth[2], omega));
  for (int k : {0, 5})
    s.graph.position_priors.push_back(
        PositionPriorFactor<G>::make(k, s.truth[k].translation(), omega_t));
  std::vector<G> poses;
  const std::string expected =
      "the certifiable solver takes relative-pose edges only: 1 pose priors, 2 position "
      "priors; use --solver lm";
  try {
    solveRtr(s.graph, &poses);
    ADD_FAILURE() << "expected std::invalid_argument";
  } catch (const std::invalid_argument& e) {
    EXPECT_EQ(std::string(e.what()), expected);
  }
  EXPECT_TRUE(poses.empty());  // nothing written
  EXPECT_THROW(certify(s.graph, s.truth), std::invalid_argument);
  EXPECT_THROW(sesyncMeasurements(s.graph), std::invalid_argument);
  // A one-pose graph with a prior is refused too (not the trivial-graph shortcut).
  PoseGraph<G> single;
  single.ids = {0};
  single.index[0] = 0;
  single.pose_priors.push_back(PosePriorFactor<G>::make(0, G::Identity(), omega));
  EXPECT_THROW(solveRtr(single, &poses), std::invalid_argument);
  // The batch solver takes them.
  poses = s.truth;
  EXPECT_EQ(solveBatch(s.graph, &poses).termination, Termination::kConverged);
  s.graph.pose_priors.clear();
  s.graph.position_priors.clear();
  EXPECT_NO_THROW(solveRtr(s.graph, &poses));
}

TEST(SolveRtr, GraphsWithPriorsAreRefused2D) { checkPriorsRefused<SE2>(); }
TEST(SolveRtr, GraphsWithPriorsAreRefused3D) { checkPriorsRefused<SE3>(); }

TEST(SESyncProblem, DisconnectedGraphIsRejected) {
  Synthetic<SE2> s = randomGraph<SE2>(10, 0, 0.0, 0.0, 5);
  s.graph.edges.erase(s.graph.edges.begin() + 4);  // splits 0..4 from 5..9
  std::vector<SE2> poses;
  try {
    solveRtr(s.graph, &poses);
    FAIL() << "expected std::invalid_argument";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("not connected"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("15"), std::string::npos) << e.what();  // id of index 5
  }
  EXPECT_THROW(
      solveRtr(randomGraph<SE2>(5, 1, 0, 0, 1).graph, static_cast<std::vector<SE2>*>(nullptr)),
      std::invalid_argument);
  RtrOptions bad;
  bad.initial_rank = 1;
  EXPECT_THROW(solveRtr(randomGraph<SE2>(5, 1, 0, 0, 1).graph, &poses, bad), std::invalid_argument);
}

TEST(Rtr, RandomSyntheticGraphs) {
  for (std::uint64_t seed : {11u, 12u}) {
    const Synthetic<SE2> s2 = randomGraph<SE2>(300, 150, 0.05, 0.03, seed);
    std::vector<SE2> p2;
    const RtrSummary r2 = solveRtr(s2.graph, &p2);
    EXPECT_TRUE(r2.certified) << r2.message;
    EXPECT_GE(r2.lambda_min, -RtrOptions{}.certificate_tolerance);
    // LM started at the ground truth cannot end lower than the certified optimum (up to the
    // polish's stopping tolerance: SE-Sync's 2D κ weighs rotations twice as our F does, so the
    // rounded point is a little farther from our F's minimum).
    std::vector<SE2> from_truth = s2.truth;
    solveBatch(s2.graph, &from_truth);
    EXPECT_LE(r2.F_final, objective(s2.graph, from_truth) * (1 + 1e-5));
    EXPECT_NEAR(r2.F_final, objective(s2.graph, p2), 1e-9 * r2.F_final);
    EXPECT_LE(r2.F_final, r2.F_rounded * (1 + 1e-12));

    const Synthetic<SE3> s3 = randomGraph<SE3>(150, 80, 0.05, 0.03, seed);
    std::vector<SE3> p3;
    const RtrSummary r3 = solveRtr(s3.graph, &p3);
    EXPECT_TRUE(r3.certified) << r3.message;
    std::vector<SE3> truth3 = s3.truth;
    solveBatch(s3.graph, &truth3);
    EXPECT_LE(r3.F_final, objective(s3.graph, truth3) * (1 + 1e-6));

    // SE-Sync 1.0's preconditioner (Schur form of M + λI) reaches the same certified optimum.
    RtrOptions schur;
    schur.preconditioner = SESyncPreconditioner::kDataMatrix;
    schur.preconditioner_max_condition = 1e6;
    std::vector<SE3> q3;
    const RtrSummary s3m = solveRtr(s3.graph, &q3, schur);
    EXPECT_TRUE(s3m.certified) << s3m.message;
    EXPECT_NEAR(s3m.F_final, r3.F_final, 1e-6 * r3.F_final);
  }
}

TEST(Rtr, TrivialGraphs) {
  PoseGraph2 single;
  single.ids = {7};
  single.index[7] = 0;
  single.poses = {SE2(1, 2, 0.3)};
  single.has_initial_estimate = true;
  std::vector<SE2> poses;
  const RtrSummary s = solveRtr(single, &poses);
  ASSERT_EQ(poses.size(), 1u);
  EXPECT_NEAR(poses[0].x(), 1.0, 1e-12);
  EXPECT_EQ(s.F_final, 0.0);
  // Two poses, one edge: the measurement holds exactly, the first pose stays at its value.
  Synthetic<SE3> pair = randomGraph<SE3>(2, 0, 0.0, 0.0, 3);
  pair.graph.has_initial_estimate = true;
  std::vector<SE3> p2;
  const RtrSummary s2 = solveRtr(pair.graph, &p2);
  EXPECT_TRUE(s2.certified) << s2.message;
  EXPECT_LT(s2.F_final, 1e-12);
  EXPECT_LT((p2[1].translation() - pair.truth[1].translation()).norm(), 1e-9);
}

TEST(Rtr, FindsOptimumWhereLmFromOdometryStalls) {
  const Synthetic<SE2> s = noisyRing(100, 0.5, 2);
  std::vector<SE2> lm = odometryInitialization(s.graph);
  solveBatch(s.graph, &lm);
  const double F_lm = objective(s.graph, lm);
  std::vector<SE2> rtr;
  const RtrSummary summary = solveRtr(s.graph, &rtr);
  EXPECT_TRUE(summary.certified) << summary.message;
  EXPECT_LT(summary.F_final, 0.9 * F_lm) << "LM from odometry: " << F_lm;
  // The certified answer is no worse than LM started at the ground truth.
  std::vector<SE2> from_truth = s.truth;
  solveBatch(s.graph, &from_truth);
  EXPECT_LE(summary.F_final, objective(s.graph, from_truth) * (1 + 1e-6));
}

TEST(Rtr, ClimbsTheStaircaseFromSaddles) {
  // Rotation noise this large makes rank 5 end at saddles and the relaxation inexact: the
  // staircase must escape them and solve the relaxation at a higher rank.
  const Synthetic<SE2> s = noisyRing(100, 0.5, 4);
  std::vector<SE2> rtr;
  const RtrSummary summary = solveRtr(s.graph, &rtr);
  EXPECT_TRUE(summary.relaxation_solved) << summary.message;
  EXPECT_GT(summary.rank, 5);
  EXPECT_GE(summary.lambda_min, -RtrOptions{}.certificate_tolerance);
  // Not exact: the rounded point is measurably above the relaxation, so no certificate.
  EXPECT_GT(summary.suboptimality_bound, 1e-4 * summary.sesync_objective);
  EXPECT_FALSE(summary.certified);
  std::vector<SE2> from_truth = s.truth;
  solveBatch(s.graph, &from_truth);
  EXPECT_LE(summary.F_final, objective(s.graph, from_truth) * (1 + 1e-6));
  // Starting at r = d = 2 (no slack) reaches the same relaxation value.
  RtrOptions low;
  low.initial_rank = 2;
  std::vector<SE2> rtr2;
  const RtrSummary summary2 = solveRtr(s.graph, &rtr2, low);
  EXPECT_TRUE(summary2.relaxation_solved) << summary2.message;
  EXPECT_NEAR(summary2.sesync_objective, summary.sesync_objective, 1e-5 * summary.sesync_objective);
}

TEST(Rtr, CertificateRejectsPerturbedPoint) {
  const Synthetic<SE3> s = randomGraph<SE3>(60, 40, 0.05, 0.03, 21);
  RtrOptions options;
  options.polish = false;  // the rounded relaxation optimum itself
  options.gradient_tolerance = 1e-6;
  std::vector<SE3> opt;
  const RtrSummary summary = solveRtr(s.graph, &opt, options);
  ASSERT_TRUE(summary.certified) << summary.message;
  const double at_optimum = certify(s.graph, opt);
  EXPECT_GT(at_optimum, -1e-4);
  EXPECT_LT(at_optimum, 1e-4);
  std::vector<SE3> perturbed = opt;
  std::mt19937_64 rng(5);
  for (int k = 10; k < 20; ++k) {
    perturbed[k] = perturbed[k].compose(SE3::Exp(randomTangent<SE3>(rng, 0.0, 0.5)));
  }
  const double at_perturbed = certify(s.graph, perturbed);
  EXPECT_LT(at_perturbed, -1.0) << "at the optimum: " << at_optimum;
  // At a higher rank the same point (zero-padded) gives the same certificate.
  const SESyncProblem problem(60, 3, sesyncMeasurements(s.graph));
  Eigen::MatrixXd X = Eigen::MatrixXd::Zero(180, 5);
  for (int i = 0; i < 60; ++i) X.block(3 * i, 0, 3, 3) = opt[i].rotation().transpose();
  EXPECT_NEAR(certify(problem, X), at_optimum, 1e-4);
  std::cout << "lambda_min at the optimum " << at_optimum << ", perturbed " << at_perturbed << "\n";
}

class RtrOnDataset : public ::testing::TestWithParam<std::string> {};

TEST_P(RtrOnDataset, CertifiesGlobalOptimum) {
  const std::string name = GetParam();
  if (!testing::datasetPresent(name)) {
    GTEST_SKIP() << "shared dataset absent: " << testing::datasetPath(name);
  }
  const auto table = testing::optimumTable();
  if (!table.count(name)) GTEST_SKIP() << "no reference optimum for " << name;
  const double F_star = table.at(name).F_star;
  const AnyPoseGraph any = readPoseGraphFile(testing::datasetPath(name));
  std::visit(
      [&](const auto& graph) {
        using G = typename std::decay_t<decltype(graph)>::GroupType;
        std::vector<G> poses;
        const RtrSummary s = solveRtr(graph, &poses);
        EXPECT_TRUE(s.certified) << s.message;
        EXPECT_NEAR(s.F_final, F_star, 1e-4 * F_star)
            << "rounded " << s.F_rounded << ", rank " << s.rank;
        EXPECT_NEAR(objective(graph, poses), s.F_final, 1e-9 * F_star);
      },
      any);
}

INSTANTIATE_TEST_SUITE_P(Shared, RtrOnDataset,
                         ::testing::Values("tinyGrid3D", "smallGrid3D", "MIT", "M3500"));

}  // namespace
}  // namespace arbor
