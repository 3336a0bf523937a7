// Factors of your own (core/factor_model.h, core/autodiff_factor.h, core/custom_factor.h): the
// example factors' Jacobians against central differences under x ⊞ τ, analytic against
// autodiff, Factor<G>'s whitened padded linearisation, and the refusals (bad Ω, residual too
// long, bad keys, the g2o writer, the certifiable solver). The solvers with custom factors:
// custom_factor_solvers_test.cc.
#include <cmath>
#include <memory>
#include <random>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <Eigen/Core>

#include "arbor_slam/bayestree/incremental_smoother.h"
#include "arbor_slam/core/custom_factor.h"
#include "arbor_slam/core/example_factors.h"
#include "arbor_slam/core/factor.h"
#include "arbor_slam/core/normal_equations.h"
#include "arbor_slam/core/sesync_problem.h"
#include "arbor_slam/io/pose_graph_file.h"
#include "arbor_slam/tests/custom_factor_support.h"

namespace arbor {
namespace {

using testing::randomPoint;
using testing::randomPose;
using testing::randomSpd;
using testing::rangeModel;

constexpr double kStep = 1e-6;
constexpr double kTolerance = 1e-6;

/// Every Jacobian of f at x against central differences of its error under x_k ⊞ τ.
template <class G>
void expectJacobiansMatch(const CustomFactor<G>& f, std::vector<G> x) {
  typename FactorModel<G>::Jacobians J;
  const Eigen::VectorXd e0 = f.error(x, &J);
  ASSERT_EQ(e0.size(), f.rows());
  for (int k = 0; k < f.arity(); ++k) {
    const int key = k == 0 ? f.i : f.j;
    Eigen::MatrixXd numeric(f.rows(), G::kDoF);
    for (int c = 0; c < G::kDoF; ++c) {
      typename G::Tangent tau = G::Tangent::Zero();
      tau(c) = kStep;
      std::vector<G> plus = x, minus = x;
      plus[key] = x[key].retract(tau);
      minus[key] = x[key].retract(-tau);
      numeric.col(c) = (f.error(plus) - f.error(minus)) / (2 * kStep);
    }
    const Eigen::MatrixXd analytic = J[static_cast<size_t>(k)];
    EXPECT_LT((analytic - numeric).cwiseAbs().maxCoeff(), kTolerance)
        << f.name() << " key " << k << "\nanalytic\n"
        << analytic << "\nnumeric\n"
        << numeric;
  }
}

template <class G>
class CustomFactorTest : public ::testing::Test {};
using Groups = ::testing::Types<SE2, SE3>;
TYPED_TEST_SUITE(CustomFactorTest, Groups);

TYPED_TEST(CustomFactorTest, RangeJacobiansMatchCentralDifferences) {
  using G = TypeParam;
  std::mt19937_64 rng(1);
  for (int trial = 0; trial < 20; ++trial) {
    const std::vector<G> x{randomPose<G>(rng)};
    const auto f = CustomFactor<G>::make(rangeModel<G>(randomPoint<G>(rng, 10), 4.0),
                                         Eigen::MatrixXd::Constant(1, 1, 9.0), 0);
    expectJacobiansMatch(f, x);
  }
}

TYPED_TEST(CustomFactorTest, RelativePositionJacobiansMatchAndAgree) {
  using G = TypeParam;
  constexpr int D = G::kDim;
  std::mt19937_64 rng(2);
  for (int trial = 0; trial < 20; ++trial) {
    const std::vector<G> x{randomPose<G>(rng), randomPose<G>(rng)};
    const Eigen::Matrix<double, D, 1> p = randomPoint<G>(rng, 3);
    const Eigen::MatrixXd omega = randomSpd<D>(rng);
    const auto autodiff = CustomFactor<G>::make(
        examples::RelativePositionAutoDiff<G>::Create({p}, "relative_position"), omega, 0, 1);
    const auto analytic = CustomFactor<G>::make(
        std::make_shared<const examples::RelativePositionFactor<G>>(p), omega, 0, 1);
    expectJacobiansMatch(autodiff, x);
    expectJacobiansMatch(analytic, x);
    typename FactorModel<G>::Jacobians Ja, Jb;
    EXPECT_LT((autodiff.error(x, &Ja) - analytic.error(x, &Jb)).cwiseAbs().maxCoeff(), 1e-12);
    for (int k = 0; k < 2; ++k) EXPECT_LT((Ja[k] - Jb[k]).cwiseAbs().maxCoeff(), 1e-12);
  }
}

TEST(CustomFactor, PlanarMotionJacobiansMatchAndAgree) {
  std::mt19937_64 rng(3);
  for (int trial = 0; trial < 20; ++trial) {
    const std::vector<SE3> x{randomPose<SE3>(rng)};
    const Eigen::MatrixXd omega = randomSpd<3>(rng);
    const auto autodiff = CustomFactor<SE3>::make(
        examples::PlanarMotionAutoDiff::Create({}, "planar_motion"), omega, 0);
    const auto analytic =
        CustomFactor<SE3>::make(std::make_shared<const examples::PlanarMotionFactor>(), omega, 0);
    expectJacobiansMatch(autodiff, x);
    expectJacobiansMatch(analytic, x);
    typename FactorModel<SE3>::Jacobians Ja, Jb;
    EXPECT_LT((autodiff.error(x, &Ja) - analytic.error(x, &Jb)).cwiseAbs().maxCoeff(), 1e-12);
    EXPECT_LT((Ja[0] - Jb[0]).cwiseAbs().maxCoeff(), 1e-12);
  }
  // Near planar: e ≈ [z; roll; pitch].
  const double z = 0.01, roll = 0.002, pitch = -0.003;
  const Eigen::Quaterniond q(Eigen::AngleAxisd(0.7, Eigen::Vector3d::UnitZ()) *
                             Eigen::AngleAxisd(pitch, Eigen::Vector3d::UnitY()) *
                             Eigen::AngleAxisd(roll, Eigen::Vector3d::UnitX()));
  const std::vector<SE3> x{SE3(q, Eigen::Vector3d(4, -2, z))};
  const auto f = CustomFactor<SE3>::make(std::make_shared<const examples::PlanarMotionFactor>(),
                                         Eigen::Matrix3d::Identity(), 0);
  const Eigen::Vector3d e = f.error(x);
  EXPECT_NEAR(e(0), z, 1e-15);
  EXPECT_NEAR(e(1), roll, 1e-7);  // cos β sin α
  EXPECT_NEAR(e(2), pitch, 1e-7);
}

// Factor<G>: the whitened linearisation zero-padded to kDoF rows, ‖r‖² = eᵀΩe = cost().
TYPED_TEST(CustomFactorTest, FactorLinearizesWhitenedAndPadded) {
  using G = TypeParam;
  std::mt19937_64 rng(4);
  const std::vector<G> x{randomPose<G>(rng), randomPose<G>(rng)};
  const Eigen::MatrixXd omega = randomSpd<G::kDim>(rng);
  const auto c = CustomFactor<G>::make(
      examples::RelativePositionAutoDiff<G>::Create({randomPoint<G>(rng, 2)}), omega, 0, 1);
  const Factor<G> f(c);
  EXPECT_EQ(f.kind(), FactorKind::kCustom);
  EXPECT_EQ(f.arity(), 2);
  EXPECT_EQ(f.key(1), 1);
  EXPECT_EQ(f.name(), "autodiff");
  EXPECT_TRUE(f.isFinite());
  typename Factor<G>::Linearization L;
  f.linearize(x, &L);
  typename FactorModel<G>::Jacobians J;
  const Eigen::VectorXd e = c.error(x, &J);
  EXPECT_NEAR(L.r.squaredNorm(), e.dot(omega * e), 1e-9 * (1 + f.cost(x)));
  EXPECT_NEAR(f.cost(x), e.dot(omega * e), 1e-12 * (1 + f.cost(x)));
  EXPECT_TRUE(L.r.tail(G::kDoF - G::kDim).isZero(0.0));
  for (int k = 0; k < 2; ++k) {
    EXPECT_TRUE(L.A[k].bottomRows(G::kDoF - G::kDim).isZero(0.0));
    const Eigen::MatrixXd H = L.A[k].transpose() * L.A[k];
    const Eigen::MatrixXd expected = J[k].transpose() * omega * J[k];
    EXPECT_LT((H - expected).cwiseAbs().maxCoeff(), 1e-9 * (1 + expected.norm()));
  }
  Factor<G> moved = f;
  moved.setKeys(3, 5);
  EXPECT_EQ(moved.key(0), 3);
  EXPECT_EQ(moved.key(1), 5);
}

// A model of one's own that claims more rows than kDoF.
class TooLong final : public FactorModel<SE2> {
 public:
  int rows() const override { return 4; }
  int arity() const override { return 1; }
  std::string name() const override { return "too_long"; }
  void evaluate(const std::array<const SE2*, 2>&, Residual* e, Jacobians*) const override {
    e->setZero(3);
  }
};

// A model whose error has fewer entries than it says.
class WrongSize final : public FactorModel<SE2> {
 public:
  int rows() const override { return 2; }
  int arity() const override { return 1; }
  std::string name() const override { return "wrong_size"; }
  void evaluate(const std::array<const SE2*, 2>&, Residual* e, Jacobians*) const override {
    e->setZero(1);
  }
};

template <class F>
std::string thrownBy(F&& f) {
  try {
    f();
  } catch (const std::invalid_argument& e) {
    return e.what();
  }
  return "(nothing thrown)";
}

TEST(CustomFactorInput, BadInputIsRefusedNamingTheValue) {
  const auto model = rangeModel<SE2>(Eigen::Vector2d(1, 2), 3.0);
  const Eigen::MatrixXd one = Eigen::MatrixXd::Identity(1, 1);
  const auto has = [](const std::string& message, const std::string& part) {
    return message.find(part) != std::string::npos;
  };
  const double nan = std::nan("");
  std::string m = thrownBy([&] { CustomFactor<SE2>::make(model, one * nan, 0); });
  EXPECT_TRUE(has(m, "'range'") && has(m, "information matrix") && has(m, "NaN")) << m;
  m = thrownBy([&] { CustomFactor<SE2>::make(model, -one, 0); });
  EXPECT_TRUE(has(m, "positive definite")) << m;
  m = thrownBy([&] { CustomFactor<SE2>::make(model, Eigen::MatrixXd::Identity(2, 2), 0); });
  EXPECT_TRUE(has(m, "information matrix 2x2 for a residual of 1 rows")) << m;
  m = thrownBy([&] { CustomFactor<SE2>::make(std::make_shared<const TooLong>(), one, 0); });
  EXPECT_TRUE(has(m, "'too_long'") && has(m, "residual of 4 rows, outside 1..3")) << m;
  m = thrownBy([&] { CustomFactor<SE2>::make(model, one, -2); });
  EXPECT_TRUE(has(m, "pose index -2")) << m;
  m = thrownBy([&] { CustomFactor<SE2>::make(model, one, 0, 4); });
  EXPECT_TRUE(has(m, "unary, given a second pose index 4")) << m;
  const auto binary = examples::RelativePositionAutoDiff<SE2>::Create({Eigen::Vector2d(1, 0)});
  m = thrownBy([&] { CustomFactor<SE2>::make(binary, Eigen::Matrix2d::Identity(), 3, 3); });
  EXPECT_TRUE(has(m, "second pose index 3 equals the first")) << m;
  m = thrownBy([&] { CustomFactor<SE2>::make(nullptr, one, 0); });
  EXPECT_TRUE(has(m, "no model")) << m;
  const auto wrong =
      CustomFactor<SE2>::make(std::make_shared<const WrongSize>(), Eigen::Matrix2d::Identity(), 0);
  const std::vector<SE2> x(1);
  m = thrownBy([&] { wrong.cost(x); });
  EXPECT_TRUE(has(m, "'wrong_size': error of 1 entries, expected 2")) << m;

  // Keys out of range: the smoother and the batch solver name them.
  IncrementalSmoother<SE2> s;
  s.addPose(SE2());
  m = thrownBy([&] { s.addFactor(CustomFactor<SE2>::make(model, one, 3)); });
  EXPECT_TRUE(has(m, "addFactor(range 3)") && has(m, "pose index out of range")) << m;
  PoseGraph2 graph;
  graph.ids = {7};
  graph.index[7] = 0;
  graph.poses.resize(1);
  graph.custom_factors.push_back(
      CustomFactor<SE2>::make(binary, Eigen::Matrix2d::Identity(), 0, 2));
  m = thrownBy([&] { gaugeProblem(graph); });
  EXPECT_TRUE(has(m, "custom factor 0 ('autodiff') is on pose index 2, outside 0..0")) << m;
}

// What cannot hold a custom factor says so, naming it: g2o files and the certifiable solver.
TEST(CustomFactorInput, WritersAndTheCertifiableSolverRefuse) {
  PoseGraph2 graph;
  graph.ids = {0, 1};
  graph.index = {{0, 0}, {1, 1}};
  graph.poses = {SE2(), SE2(1, 0, 0)};
  graph.edges.push_back(
      RelativePoseEdge<SE2>::make(0, 1, SE2(1, 0, 0), Eigen::Matrix3d::Identity()));
  graph.custom_factors.push_back(CustomFactor<SE2>::make(
      rangeModel<SE2>(Eigen::Vector2d(0, 5), 5.0), Eigen::MatrixXd::Identity(1, 1), 1));
  std::ostringstream out;
  std::string m = thrownBy([&] { writeG2o(out, graph, graph.poses); });
  EXPECT_NE(m.find("custom factor 0 ('range', of 1) has no g2o tag"), std::string::npos) << m;
  EXPECT_TRUE(out.str().empty());
  m = thrownBy([&] { requireRelativePoseEdgesOnly(graph); });
  EXPECT_NE(m.find("1 custom factor(s) (the first 'range')"), std::string::npos) << m;
  EXPECT_NE(m.find("--solver lm"), std::string::npos) << m;
}

}  // namespace
}  // namespace arbor
