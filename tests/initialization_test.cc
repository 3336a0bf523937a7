#include "arbor_slam/core/initialization.h"

#include <cmath>
#include <random>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include <gtest/gtest.h>

namespace arbor {
namespace {

template <class G>
using Tangent = typename G::Tangent;
template <class G>
constexpr int kRotDoF = G::kDoF - G::kDim;

/// A tangent with translational entries N(0, σ_t) (+ `forward` on the first axis) and
/// rotational entries N(0, σ_r).
template <class G>
Tangent<G> randomTangent(std::mt19937* rng, double sigma_t, double sigma_r, double forward = 0) {
  std::normal_distribution<double> normal(0.0, 1.0);
  Tangent<G> tau;
  for (int k = 0; k < G::kDoF; ++k) tau(k) = normal(*rng) * (k < G::kDim ? sigma_t : sigma_r);
  tau(0) += forward;
  return tau;
}

template <class G>
typename RelativePoseEdge<G>::Matrix randomInformation(std::mt19937* rng) {
  using Matrix = typename RelativePoseEdge<G>::Matrix;
  std::uniform_real_distribution<double> uniform(-1.0, 1.0);
  Matrix A;
  for (int k = 0; k < A.size(); ++k) A.data()[k] = uniform(*rng);
  return A * A.transpose() + Matrix::Identity();
}

template <class G>
double rotationError(const G& a, const G& b) {
  return a.between(b).Log().template tail<kRotDoF<G>>().norm();
}

template <class G>
double translationError(const G& a, const G& b) {
  return (a.translation() - b.translation()).norm();
}

template <class G>
double maxPoseError(const std::vector<G>& a, const std::vector<G>& b) {
  EXPECT_EQ(a.size(), b.size());
  double worst = 0.0;
  for (std::size_t k = 0; k < std::min(a.size(), b.size()); ++k) {
    worst = std::max({worst, rotationError(a[k], b[k]), translationError(a[k], b[k])});
  }
  return worst;
}

/// A graph over `n` poses with ids 10k + 3 (ascending, not contiguous) and the given edges.
template <class G>
PoseGraph<G> emptyGraph(int n) {
  PoseGraph<G> graph;
  for (int k = 0; k < n; ++k) {
    graph.ids.push_back(10 * k + 3);
    graph.index[10 * k + 3] = k;
  }
  return graph;
}

/// A random walk of n poses (first at a random non-identity pose), odometry edges (every
/// third one stored reversed, j → i), `loops` random loop closures, and one self-loop;
/// measurements exact, information random.
/// With `isotropic_translation`, each Ω has a translational block τ I (τ random per edge).
template <class G>
std::pair<PoseGraph<G>, std::vector<G>> exactRandomGraph(int n, int loops, unsigned seed,
                                                         bool isotropic_translation = false) {
  std::mt19937 rng(seed);
  std::vector<G> truth{G::Exp(randomTangent<G>(&rng, 5.0, 1.0))};
  for (int k = 1; k < n; ++k) {
    truth.push_back(truth.back().compose(G::Exp(randomTangent<G>(&rng, 0.3, 0.4, 1.0))));
  }
  PoseGraph<G> graph = emptyGraph<G>(n);
  auto addExact = [&](int i, int j) {
    auto omega = randomInformation<G>(&rng);
    if (isotropic_translation) {
      omega.template topRows<G::kDim>().setZero();
      omega.template leftCols<G::kDim>().setZero();
      omega.template topLeftCorner<G::kDim, G::kDim>().diagonal().setConstant(
          std::uniform_real_distribution<double>(0.5, 50.0)(rng));
    }
    graph.edges.push_back(RelativePoseEdge<G>::make(i, j, truth[i].between(truth[j]), omega));
  };
  for (int k = 1; k < n; ++k) {
    if (k % 3 == 0) {
      addExact(k, k - 1);
    } else {
      addExact(k - 1, k);
    }
  }
  std::uniform_int_distribution<int> pick(0, n - 1);
  for (int l = 0; l < loops; ++l) {
    const int i = pick(rng), j = pick(rng);
    if (std::abs(i - j) > 1) addExact(i, j);
  }
  graph.edges.push_back(RelativePoseEdge<G>::make(n / 2, n / 2, G::Identity(),
                                                  RelativePoseEdge<G>::Matrix::Identity()));
  return {graph, truth};
}

template <class G>
std::vector<G> relativeTo(const G& origin, const std::vector<G>& poses) {
  std::vector<G> out;
  for (const G& x : poses) out.push_back(origin.inverse().compose(x));
  return out;
}

constexpr InitMethod kComputedMethods[] = {InitMethod::kOdometry, InitMethod::kSpanningTree,
                                           InitMethod::kChordal};

template <class G>
class InitializationTest : public ::testing::Test {};
using Groups = ::testing::Types<SE2, SE3>;
TYPED_TEST_SUITE(InitializationTest, Groups);

TYPED_TEST(InitializationTest, ExactMeasurementsReproduceGroundTruthAtFileGauge) {
  using G = TypeParam;
  for (unsigned seed : {1u, 2u, 3u}) {
    auto [graph, truth] = exactRandomGraph<G>(80, 30, seed);
    graph.has_initial_estimate = true;
    graph.poses = truth;
    for (InitMethod m : kComputedMethods) {
      const std::vector<G> x = initialize(graph, m);
      EXPECT_LT(maxPoseError(x, truth), 1e-9) << toString(m) << " seed " << seed;
    }
  }
}

// Ω_tt = τ I on every edge takes chordal's scalar translation system.
TYPED_TEST(InitializationTest, ExactMeasurementsWithIsotropicTranslationInformation) {
  using G = TypeParam;
  auto [graph, truth] = exactRandomGraph<G>(80, 30, 4, /*isotropic_translation=*/true);
  graph.has_initial_estimate = true;
  graph.poses = truth;
  for (InitMethod m : kComputedMethods) {
    EXPECT_LT(maxPoseError(initialize(graph, m), truth), 1e-9) << toString(m);
  }
}

TYPED_TEST(InitializationTest, ExactMeasurementsWithoutEstimatePutFirstPoseAtIdentity) {
  using G = TypeParam;
  auto [graph, truth] = exactRandomGraph<G>(60, 20, 7);
  const std::vector<G> expected = relativeTo(truth[0], truth);
  for (InitMethod m : kComputedMethods) {
    const std::vector<G> x = initialize(graph, m);
    EXPECT_LT(maxPoseError(x, expected), 1e-9) << toString(m);
    EXPECT_LT(maxPoseError<G>({x[0]}, {G::Identity()}), 1e-15) << toString(m);
  }
}

TYPED_TEST(InitializationTest, FixedPosesHoldTheirFileValuesOthersIgnored) {
  using G = TypeParam;
  auto [graph, truth] = exactRandomGraph<G>(60, 20, 11);
  std::mt19937 rng(99);
  graph.has_initial_estimate = true;
  graph.fixed = {17, 40, 5};
  graph.poses.clear();
  for (int k = 0; k < graph.numPoses(); ++k) {
    const bool fixed = k == 17 || k == 40 || k == 5;
    graph.poses.push_back(fixed ? truth[k] : G::Exp(randomTangent<G>(&rng, 3.0, 1.0)));
  }
  for (InitMethod m : kComputedMethods) {
    const std::vector<G> x = initialize(graph, m);
    EXPECT_LT(maxPoseError(x, truth), 1e-9) << toString(m);
    for (int k : graph.fixed) {
      EXPECT_LT(maxPoseError<G>({x[k]}, {truth[k]}), 1e-15) << toString(m) << " pose " << k;
    }
  }
  // Without an initial estimate only the first fixed pose is a gauge, at the identity.
  graph.has_initial_estimate = false;
  const std::vector<G> expected = relativeTo(truth[17], truth);
  for (InitMethod m : kComputedMethods) {
    EXPECT_LT(maxPoseError(initialize(graph, m), expected), 1e-9) << toString(m);
  }
}

// Noisy (inconsistent) measurements: 0→1, 0→3 (a loop closure before the chain reaches 3),
// 2→1 (a reversed chain edge), 2→3, then a second 1→2 edge that odometry must not use.
TYPED_TEST(InitializationTest, OdometryFollowsChainAndSpanningTreeBreadthFirst) {
  using G = TypeParam;
  std::mt19937 rng(5);
  auto z = [&] { return G::Exp(randomTangent<G>(&rng, 1.0, 0.5, 1.0)); };
  const G z01 = z(), z03 = z(), z21 = z(), z23 = z(), z12b = z();
  const auto I = RelativePoseEdge<G>::Matrix::Identity();
  PoseGraph<G> graph = emptyGraph<G>(4);
  graph.edges = {RelativePoseEdge<G>::make(0, 1, z01, I), RelativePoseEdge<G>::make(0, 3, z03, I),
                 RelativePoseEdge<G>::make(2, 1, z21, I), RelativePoseEdge<G>::make(2, 3, z23, I),
                 RelativePoseEdge<G>::make(1, 2, z12b, I)};
  graph.has_initial_estimate = true;
  const G x0 = z();
  graph.poses = {x0, z(), z(), z()};

  const G odo1 = x0.compose(z01);
  const G odo2 = odo1.compose(z21.inverse());
  const G odo3 = odo2.compose(z23);
  const std::vector<G> odometry = odometryInitialization(graph);
  EXPECT_LT(maxPoseError(odometry, {x0, odo1, odo2, odo3}), 1e-12);

  const std::vector<G> tree = spanningTreeInitialization(graph);
  EXPECT_LT(maxPoseError(tree, {x0, x0.compose(z01), x0.compose(z01).compose(z21.inverse()),
                                x0.compose(z03)}),
            1e-12);
  EXPECT_GT(maxPoseError<G>({odometry[3]}, {tree[3]}), 1e-3);  // the two really differ
}

// No edge between poses 2 and 3 (ids 23, 33). First pose 4 is reached by the loop closure
// 1→4 and pose 3 follows the chain edge 4→3 from it; then, with an edge 0→3 added, pose 3 is
// reached first (from pose 0) and pose 4 follows the chain edge backwards.
TYPED_TEST(InitializationTest, OdometryBridgesGapsThroughTheSpanningTree) {
  using G = TypeParam;
  std::mt19937 rng(8);
  auto z = [&] { return G::Exp(randomTangent<G>(&rng, 1.0, 0.5, 1.0)); };
  const G z01 = z(), z12 = z(), z43 = z(), z14 = z(), z03 = z();
  const auto I = RelativePoseEdge<G>::Matrix::Identity();
  PoseGraph<G> graph = emptyGraph<G>(5);
  graph.edges = {RelativePoseEdge<G>::make(0, 1, z01, I), RelativePoseEdge<G>::make(1, 2, z12, I),
                 RelativePoseEdge<G>::make(4, 3, z43, I), RelativePoseEdge<G>::make(1, 4, z14, I)};
  const G x1 = z01, x2 = z01.compose(z12), x4 = z01.compose(z14), x3 = x4.compose(z43);
  EXPECT_LT(maxPoseError(odometryInitialization(graph), {G::Identity(), x1, x2, x3, x4}), 1e-12);

  graph.edges.push_back(RelativePoseEdge<G>::make(0, 3, z03, I));
  EXPECT_LT(maxPoseError(odometryInitialization(graph),
                         {G::Identity(), x1, x2, z03, z03.compose(z43.inverse())}),
            1e-12);
  // The spanning tree takes pose 4 from pose 1 instead.
  EXPECT_LT(maxPoseError(spanningTreeInitialization(graph), {G::Identity(), x1, x2, z03, x4}),
            1e-12);
}

// A pose in the middle of the chain as the gauge: the chain runs both ways from it.
TYPED_TEST(InitializationTest, OdometryRunsBackwardsFromAMiddleGauge) {
  using G = TypeParam;
  std::mt19937 rng(13);
  auto z = [&] { return G::Exp(randomTangent<G>(&rng, 1.0, 0.5, 1.0)); };
  const G z01 = z(), z21 = z(), z23 = z(), z03 = z();
  const auto I = RelativePoseEdge<G>::Matrix::Identity();
  PoseGraph<G> graph = emptyGraph<G>(4);
  graph.edges = {RelativePoseEdge<G>::make(0, 3, z03, I), RelativePoseEdge<G>::make(0, 1, z01, I),
                 RelativePoseEdge<G>::make(2, 1, z21, I), RelativePoseEdge<G>::make(2, 3, z23, I)};
  graph.fixed = {2};
  const G x1 = z21, x0 = x1.compose(z01.inverse()), x3 = z23;
  EXPECT_LT(maxPoseError(odometryInitialization(graph), {x0, x1, G::Identity(), x3}), 1e-12);
}

// Several laps of a ring with loop closures to the previous lap; every measurement's rotation
// is perturbed. Chordal rotations must beat the odometry chain on average.
TYPED_TEST(InitializationTest, ChordalBeatsOdometryRotationsOnNoisyLoops) {
  using G = TypeParam;
  constexpr int kRing = 24, kLaps = 4, n = kRing * kLaps;
  double odometry_error = 0.0, chordal_error = 0.0;
  const unsigned seeds[] = {21u, 22u, 23u, 24u, 25u};
  for (unsigned seed : seeds) {
    std::mt19937 rng(seed);
    Tangent<G> step = Tangent<G>::Zero();
    step(0) = 1.0;
    step(G::kDoF - 1) = 2.0 * M_PI / kRing;  // turn about the last rotation axis
    std::vector<G> truth{G::Identity()};
    for (int k = 1; k < n; ++k) {
      truth.push_back(truth.back().compose(G::Exp(step + randomTangent<G>(&rng, 0.05, 0.05))));
    }
    PoseGraph<G> graph = emptyGraph<G>(n);
    auto addNoisy = [&](int i, int j) {
      const G noise = G::Exp(randomTangent<G>(&rng, 0.01, 0.05));
      graph.edges.push_back(RelativePoseEdge<G>::make(i, j,
                                                      truth[i].between(truth[j]).compose(noise),
                                                      RelativePoseEdge<G>::Matrix::Identity()));
    };
    for (int k = 1; k < n; ++k) addNoisy(k - 1, k);
    for (int k = kRing; k < n; ++k) addNoisy(k - kRing, k);
    graph.has_initial_estimate = true;
    graph.poses = truth;

    const std::vector<G> odometry = odometryInitialization(graph);
    const std::vector<G> chordal = chordalInitialization(graph);
    for (int k = 0; k < n; ++k) {
      odometry_error += rotationError(odometry[k], truth[k]) / (n * std::size(seeds));
      chordal_error += rotationError(chordal[k], truth[k]) / (n * std::size(seeds));
    }
  }
  this->RecordProperty("odometry_mean_rotation_error", std::to_string(odometry_error));
  this->RecordProperty("chordal_mean_rotation_error", std::to_string(chordal_error));
  EXPECT_LT(chordal_error, odometry_error);
  EXPECT_GT(chordal_error, 0.0);
}

TYPED_TEST(InitializationTest, DisconnectedGraphNamesTheUnreachablePose) {
  using G = TypeParam;
  const auto I = RelativePoseEdge<G>::Matrix::Identity();
  PoseGraph<G> graph = emptyGraph<G>(5);  // ids 3 13 23 33 43
  graph.edges = {RelativePoseEdge<G>::make(0, 1, G::Identity(), I),
                 RelativePoseEdge<G>::make(2, 3, G::Identity(), I),
                 RelativePoseEdge<G>::make(1, 4, G::Identity(), I)};
  // Without `fixed` every component is anchored at its first pose (gaugeIndices), at the
  // identity.
  for (InitMethod m : kComputedMethods) {
    const std::vector<G> x = initialize(graph, m);
    EXPECT_LT(maxPoseError(x, std::vector<G>(5, G::Identity())), 1e-12) << toString(m);
  }
  // An explicit gauge in the first component leaves the second one unanchored.
  graph.fixed = {0};
  for (InitMethod m : kComputedMethods) {
    try {
      initialize(graph, m);
      ADD_FAILURE() << toString(m) << " accepted a disconnected graph";
    } catch (const std::invalid_argument& e) {
      const std::string what = e.what();
      EXPECT_NE(what.find("pose 23 "), std::string::npos) << what;
      EXPECT_NE(what.find("not connected"), std::string::npos) << what;
    }
  }
}

template <int m>
Eigen::Matrix<double, m, m> priorInformation(std::mt19937* rng) {
  std::uniform_real_distribution<double> uniform(-1.0, 1.0);
  Eigen::Matrix<double, m, m> A;
  for (int k = 0; k < A.size(); ++k) A.data()[k] = uniform(*rng);
  return A * A.transpose() + Eigen::Matrix<double, m, m>::Identity();
}

// A pose prior puts the guess in its frame: on the first pose (the root), or on a later one
// (then the root of the component), with a sensor offset.
TYPED_TEST(InitializationTest, PosePriorPutsTheGuessInThePriorsFrame) {
  using G = TypeParam;
  auto [graph, truth] = exactRandomGraph<G>(40, 15, 51);
  std::mt19937 rng(52);
  const G offset = G::Exp(randomTangent<G>(&rng, 0.5, 0.5));
  for (int k : {0, 13}) {
    graph.pose_priors = {PosePriorFactor<G>::make(k, truth[k].compose(offset),
                                                  priorInformation<G::kDoF>(&rng), offset)};
    ASSERT_TRUE(graph.gaugeIndices().empty());
    for (InitMethod m : kComputedMethods) {
      const std::vector<G> x = initialize(graph, m);
      EXPECT_LT(maxPoseError(x, truth), 1e-9) << toString(m) << ", prior on pose " << k;
      EXPECT_LT(objective(graph, x), 1e-12) << toString(m);
    }
  }
  // A gauge pose (fixed, no file values) with a pose prior starts at the prior's value.
  graph.fixed = {13};
  for (InitMethod m : kComputedMethods)
    EXPECT_LT(maxPoseError(initialize(graph, m), truth), 1e-9) << toString(m);
}

// Position priors alone (every 10th pose): the guess is aligned onto them rigidly; exact
// measurements and priors give the truth.
TYPED_TEST(InitializationTest, PositionPriorsAlignTheGuess) {
  using G = TypeParam;
  constexpr int d = G::kDim;
  auto [graph, truth] = exactRandomGraph<G>(50, 20, 53);
  std::mt19937 rng(54);
  for (int k = 0; k < 50; k += 10)
    graph.position_priors.push_back(
        PositionPriorFactor<G>::make(k, truth[k].translation(), priorInformation<d>(&rng)));
  ASSERT_TRUE(graph.gaugeIndices().empty());
  for (InitMethod m : kComputedMethods) {
    const std::vector<G> x = initialize(graph, m);
    EXPECT_LT(maxPoseError(x, truth), 1e-9) << toString(m);
  }
  // With noisy prior positions the alignment is the weighted least-squares fit: no rigid
  // motion of the guess lowers the priors' cost Σ wₖ‖R qₖ + t − pₖ‖² with isotropic weights.
  for (auto& p : graph.position_priors) {
    p = PositionPriorFactor<G>::make(
        p.i, p.position + randomTangent<G>(&rng, 0.5, 0.0).template head<d>(),
        (1.0 + p.i) * Eigen::Matrix<double, d, d>::Identity());
  }
  const std::vector<G> x = initialize(graph, InitMethod::kSpanningTree);
  auto priorsCost = [&](const std::vector<G>& poses) {
    double f = 0;
    for (const auto& p : graph.position_priors) f += p.cost(poses[p.i]);
    return f;
  };
  const double aligned = priorsCost(x);
  for (int trial = 0; trial < 20; ++trial) {
    const G move = G::Exp(randomTangent<G>(&rng, 0.05, 0.01));
    std::vector<G> moved = x;
    for (auto& y : moved) y = move.compose(y);
    EXPECT_GE(priorsCost(moved), aligned * (1 - 1e-12)) << "trial " << trial;
  }
}

// Too few position priors to fix the rotation (one): the component is anchored at its first
// pose, and the guess (first pose at the identity rotation) is only translated onto them.
TYPED_TEST(InitializationTest, FewPositionPriorsOnlyTranslateTheGuess) {
  using G = TypeParam;
  auto [graph, truth] = exactRandomGraph<G>(30, 10, 55);
  const typename G::Translation p = truth[20].translation();
  graph.position_priors = {
      PositionPriorFactor<G>::make(20, p, Eigen::Matrix<double, G::kDim, G::kDim>::Identity())};
  ASSERT_EQ(graph.gaugeIndices(), std::vector<int>{0});
  for (InitMethod m : kComputedMethods) {
    const std::vector<G> x = initialize(graph, m);
    EXPECT_LT((x[20].translation() - p).norm(), 1e-9) << toString(m);
    EXPECT_LT(rotationError(x[0], G::Identity()), 1e-12) << toString(m);
    // The shape is the truth's: truth relative to its first pose, then translated.
    const std::vector<G> shape = relativeTo(truth[0], truth);
    for (int k = 1; k < 30; ++k)
      EXPECT_LT(maxPoseError<G>({x[0].between(x[k])}, {shape[k]}), 1e-9) << toString(m);
  }
}

// A component with priors too weak to fix its gauge and no gauge pose (graph.fixed elsewhere)
// is refused, naming its first pose.
TYPED_TEST(InitializationTest, ComponentWithWeakPriorsAndNoGaugeIsRefused) {
  using G = TypeParam;
  const auto I = RelativePoseEdge<G>::Matrix::Identity();
  PoseGraph<G> graph = emptyGraph<G>(4);  // ids 3 13 23 33
  graph.edges = {RelativePoseEdge<G>::make(0, 1, G::Identity(), I),
                 RelativePoseEdge<G>::make(2, 3, G::Identity(), I)};
  graph.fixed = {0};
  graph.position_priors = {PositionPriorFactor<G>::make(
      3, G::Translation::Ones(), Eigen::Matrix<double, G::kDim, G::kDim>::Identity())};
  for (InitMethod m : kComputedMethods) {
    try {
      initialize(graph, m);
      ADD_FAILURE() << toString(m) << " accepted an unanchored component";
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find("pose 23 "), std::string::npos) << e.what();
    }
  }
  // A pose prior anchors it: the component starts at the prior's value.
  std::mt19937 rng(5);
  const G z = G::Exp(randomTangent<G>(&rng, 1.0, 1.0));
  graph.pose_priors = {PosePriorFactor<G>::make(3, z, I)};
  for (InitMethod m : kComputedMethods) {
    const std::vector<G> x = initialize(graph, m);
    EXPECT_LT(maxPoseError<G>({x[2], x[3]}, {z, z}), 1e-9) << toString(m);
  }
}

TYPED_TEST(InitializationTest, TrivialGraphs) {
  using G = TypeParam;
  PoseGraph<G> empty;
  for (InitMethod m : kComputedMethods) EXPECT_TRUE(initialize(empty, m).empty());
  PoseGraph<G> single = emptyGraph<G>(1);
  std::mt19937 rng(3);
  const G x = G::Exp(randomTangent<G>(&rng, 1.0, 1.0));
  for (InitMethod m : kComputedMethods) {
    single.has_initial_estimate = false;
    EXPECT_LT(maxPoseError(initialize(single, m), {G::Identity()}), 1e-15);
    single.has_initial_estimate = true;
    single.poses = {x};
    EXPECT_LT(maxPoseError(initialize(single, m), {x}), 1e-15);
  }
}

TYPED_TEST(InitializationTest, FileMethodReturnsPosesOrRefuses) {
  using G = TypeParam;
  auto [graph, truth] = exactRandomGraph<G>(10, 3, 4);
  EXPECT_THROW(initialize(graph, InitMethod::kFile), std::invalid_argument);
  graph.has_initial_estimate = true;
  graph.poses = truth;
  EXPECT_EQ(maxPoseError(initialize(graph, InitMethod::kFile), truth), 0.0);
}

TYPED_TEST(InitializationTest, MalformedGraphsAreRejected) {
  using G = TypeParam;
  auto [graph, truth] = exactRandomGraph<G>(10, 3, 4);
  graph.has_initial_estimate = true;
  graph.poses = truth;
  graph.poses.pop_back();
  for (InitMethod m : {InitMethod::kOdometry, InitMethod::kSpanningTree, InitMethod::kChordal,
                       InitMethod::kFile}) {
    EXPECT_THROW(initialize(graph, m), std::invalid_argument) << toString(m);
  }
  graph.poses = truth;
  graph.edges[2].j = 10;
  for (InitMethod m : kComputedMethods) {
    EXPECT_THROW(initialize(graph, m), std::invalid_argument) << toString(m);
  }
  graph.edges[2].j = 2;
  graph.fixed = {12};
  for (InitMethod m : kComputedMethods) {
    EXPECT_THROW(initialize(graph, m), std::invalid_argument) << toString(m);
  }
}

TEST(InitMethodTest, ParseAndToStringRoundTrip) {
  for (InitMethod m : {InitMethod::kOdometry, InitMethod::kSpanningTree, InitMethod::kChordal,
                       InitMethod::kFile}) {
    EXPECT_EQ(parseInitMethod(toString(m)), m);
  }
  EXPECT_EQ(toString(InitMethod::kSpanningTree), "spanning-tree");
  EXPECT_EQ(parseInitMethod("chordal"), InitMethod::kChordal);
  try {
    parseInitMethod("spanning_trees");
    ADD_FAILURE() << "accepted an unknown method";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("'spanning_trees'"), std::string::npos) << e.what();
  }
  EXPECT_THROW(parseInitMethod(""), std::invalid_argument);
  EXPECT_THROW(parseInitMethod("Chordal"), std::invalid_argument);
}

}  // namespace
}  // namespace arbor
