// Pieces shared by the tests of the smoother's units (bayestree/bayes_tree.h, linear_factors.h,
// top_elimination.h, fold_in.h, partial_solve.h): a small random SE(2) graph in linearised form,
// its dense Hessian, a whole-graph elimination into a Bayes tree, and the dense solve.
#pragma once

#include <random>
#include <vector>

#include <Eigen/Cholesky>
#include <Eigen/Core>

#include "arbor_slam/bayestree/bayes_tree.h"
#include "arbor_slam/bayestree/linear_factors.h"
#include "arbor_slam/bayestree/top_elimination.h"
#include "arbor_slam/bayestree/update_threads.h"
#include "arbor_slam/core/factor.h"
#include "arbor_slam/core/se2.h"
#include "random_graphs.h"

namespace arbor::testing {

/// A small SE(2) problem: n poses (pose 0 fixed), a chain plus loop closures and a pose prior,
/// linearised at a perturbed θ, with every unit's shared state.
struct SmallProblem {
  static constexpr int D = 3;
  std::vector<SE2> theta;
  std::vector<char> fixed;
  bayestree::LinearizedFactors<SE2> factors;
  bayestree::BayesTree<D> tree;
  bayestree::UpdateThreads threads;

  SmallProblem(int n, int closures, unsigned seed, int lanes = 1) : threads(lanes) {
    std::mt19937_64 rng(seed);
    std::uniform_int_distribution<int> pick(0, n - 1);
    std::vector<SE2> truth(n);
    for (int v = 1; v < n; ++v)
      truth[v] = truth[v - 1].compose(SE2::Exp(randomTangent<SE2>(rng, 1.0, 0.3)));
    for (int v = 0; v < n; ++v) {
      theta.push_back(v == 0 ? truth[v] : truth[v].retract(randomTangent<SE2>(rng, 0.1, 0.05)));
      fixed.push_back(v == 0);
      addVariable();
    }
    auto edge = [&](int i, int j) {
      factors.add(RelativePoseEdge<SE2>::make(i, j, truth[i].inverse().compose(truth[j]),
                                              randomInformation<SE2>(rng)));
    };
    for (int v = 1; v < n; ++v) edge(v - 1, v);
    for (int k = 0; k < closures; ++k) {
      const int i = pick(rng), j = pick(rng);
      if (i != j) edge(std::min(i, j), std::max(i, j));
    }
    factors.add(PosePriorFactor<SE2>::make(n / 2, truth[n / 2], randomInformation<SE2>(rng)));
  }

  int n() const { return static_cast<int>(theta.size()); }
  void addVariable() {
    tree.addVariable();
    factors.addVariable();
    threads.addVariable();
  }
  void linearizeAll() {
    std::vector<int> all;
    for (int f = 0; f < factors.numFactors(); ++f) all.push_back(f);
    for (int f : all) factors.linearize(f, theta);
  }
  /// The non-fixed variables.
  std::vector<int> variables() const {
    std::vector<int> out;
    for (int v = 0; v < n(); ++v)
      if (!fixed[v]) out.push_back(v);
    return out;
  }
  /// The whole graph as the top: ordered (unconstrained) and eliminated into `tree`.
  typename bayestree::TopElimination<SE2>::Output eliminateAll(
      bayestree::TopElimination<SE2>* elimination) {
    const std::vector<int> top = variables(), orphans, none;
    const typename bayestree::TopElimination<SE2>::Input in{top,   orphans, nullptr, none,
                                                            theta, fixed,   1 << 30};
    return elimination->run(in, &tree, &factors, &threads);
  }

  /// The dense Hessian H = Σ AᵀA and g = −Σ Aᵀr over pose indices (fixed poses' rows zero, their
  /// diagonal the identity, so H is invertible), from the factors' current linearisation.
  void denseSystem(Eigen::MatrixXd* H, Eigen::VectorXd* g) const {
    H->setZero(n() * D, n() * D);
    g->setZero(n() * D);
    for (int f = 0; f < factors.numFactors(); ++f) {
      const Factor<SE2>& e = factors.factors[f];
      typename Factor<SE2>::Linearization A;
      e.linearize(theta, &A);
      for (int k = 0; k < e.arity(); ++k) {
        if (fixed[e.key(k)]) continue;
        g->segment<D>(e.key(k) * D) -= A.A[k].transpose() * A.r;
        for (int l = 0; l < e.arity(); ++l)
          if (!fixed[e.key(l)])
            H->block<D, D>(e.key(k) * D, e.key(l) * D) += A.A[k].transpose() * A.A[l];
      }
    }
    for (int v = 0; v < n(); ++v)
      if (fixed[v]) H->block<D, D>(v * D, v * D).setIdentity();
  }
  /// The Gauss–Newton step H⁻¹g (zero on fixed poses).
  Eigen::VectorXd denseStep() const {
    Eigen::MatrixXd H;
    Eigen::VectorXd g;
    denseSystem(&H, &g);
    return H.ldlt().solve(g);
  }
  /// The tree's conditionals as one matrix over pose indices: R_(f,f) = R, R_(f,s) = S per
  /// clique, and d (fixed poses' rows: the identity and 0), so RᵀR = H and Rᵀd = g.
  void treeFactor(Eigen::MatrixXd* R, Eigen::VectorXd* d) const {
    R->setZero(n() * D, n() * D);
    d->setZero(n() * D);
    for (int v = 0; v < n(); ++v)
      if (fixed[v]) R->block<D, D>(v * D, v * D).setIdentity();
    for (const auto& c : tree.cliques) {
      if (!c.in_use) continue;
      const Eigen::MatrixXd Rc = c.R(), Sc = c.S();
      for (size_t a = 0; a < c.frontals.size(); ++a) {
        const int row = c.frontals[a] * D;
        d->segment<D>(row) = c.d().segment<D>(a * D);
        for (size_t b = 0; b < c.frontals.size(); ++b)
          R->block<D, D>(row, c.frontals[b] * D) = Rc.block<D, D>(a * D, b * D);
        for (size_t b = 0; b < c.separator.size(); ++b)
          R->block<D, D>(row, c.separator[b] * D) = Sc.block<D, D>(a * D, b * D);
      }
    }
  }
};

}  // namespace arbor::testing
