#include "arbor_slam/core/information.h"

#include <cmath>
#include <sstream>
#include <stdexcept>

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>

namespace arbor {

std::string informationProblem(const Eigen::MatrixXd& omega) {
  if (omega.rows() != omega.cols()) return "not square";
  if (!omega.allFinite()) {
    for (Eigen::Index k = 0; k < omega.size(); ++k) {
      if (std::isnan(omega.data()[k])) return "contains NaN";
    }
    return "contains an infinite entry";
  }
  const double scale = std::max(omega.cwiseAbs().maxCoeff(), 1e-300);
  if (scale > kMaxInformationEntry) {
    std::ostringstream os;
    os << "has an entry of magnitude " << scale << ", beyond the largest accepted ("
       << kMaxInformationEntry << ": eᵀΩe would overflow)";
    return os.str();
  }
  const double asym = (omega - omega.transpose()).cwiseAbs().maxCoeff();
  if (asym > 1e-9 * scale) {
    std::ostringstream os;
    os << "not symmetric (largest |Ω − Ωᵀ| entry " << asym << ")";
    return os.str();
  }
  Eigen::LLT<Eigen::MatrixXd> llt(omega);
  if (llt.info() != Eigen::Success) {
    Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(omega, Eigen::EigenvaluesOnly);
    std::ostringstream os;
    os << "not positive definite (smallest eigenvalue " << eig.eigenvalues()(0) << ")";
    return os.str();
  }
  return "";
}

Eigen::MatrixXd nearestPositiveDefinite(const Eigen::MatrixXd& omega, double relative_floor) {
  const Eigen::MatrixXd sym = 0.5 * (omega + omega.transpose());
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(sym);
  Eigen::VectorXd lambda = eig.eigenvalues();
  const double floor = std::max(relative_floor * lambda.cwiseAbs().maxCoeff(), 1e-12);
  lambda = lambda.cwiseMax(floor);
  Eigen::MatrixXd result =
      eig.eigenvectors() * lambda.asDiagonal() * eig.eigenvectors().transpose();
  return 0.5 * (result + result.transpose());
}

namespace {
double isotropicPrecision(const Eigen::MatrixXd& block, const char* what) {
  Eigen::LLT<Eigen::MatrixXd> llt(block);
  if (llt.info() != Eigen::Success) {
    throw std::invalid_argument(std::string("isotropic information: the ") + what +
                                " block is not positive definite");
  }
  const Eigen::MatrixXd cov = llt.solve(Eigen::MatrixXd::Identity(block.rows(), block.cols()));
  return static_cast<double>(block.rows()) / cov.trace();
}
}  // namespace

Eigen::MatrixXd isotropicInformation(const Eigen::MatrixXd& omega, int dim) {
  const int r = dim == 2 ? 1 : 3;
  const int n = dim + r;
  if (omega.rows() != n || omega.cols() != n) {
    throw std::invalid_argument("isotropic information: wrong size for dimension");
  }
  const double tau = isotropicPrecision(omega.topLeftCorner(dim, dim), "translational");
  const double kappa = isotropicPrecision(omega.bottomRightCorner(r, r), "rotational");
  Eigen::MatrixXd result = Eigen::MatrixXd::Zero(n, n);
  result.topLeftCorner(dim, dim).diagonal().setConstant(tau);
  result.bottomRightCorner(r, r).diagonal().setConstant(kappa);
  return result;
}

}  // namespace arbor
