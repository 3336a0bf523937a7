#include "arbor_slam/core/robust_kernel.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include <boost/math/distributions/chi_squared.hpp>

namespace arbor {
namespace {

constexpr KernelKind kKinds[] = {KernelKind::kNone, KernelKind::kHuber, KernelKind::kCauchy,
                                 KernelKind::kGemanMcClure, KernelKind::kTruncatedLeastSquares};

}  // namespace

std::string toString(KernelKind kind) {
  switch (kind) {
    case KernelKind::kNone:
      return "none";
    case KernelKind::kHuber:
      return "huber";
    case KernelKind::kCauchy:
      return "cauchy";
    case KernelKind::kGemanMcClure:
      return "gm";
    case KernelKind::kTruncatedLeastSquares:
      return "tls";
  }
  return "unknown";
}

KernelKind parseKernelKind(const std::string& name) {
  for (KernelKind k : kKinds)
    if (name == toString(k)) return k;
  throw std::invalid_argument("unknown kernel '" + name +
                              "' (expected none, huber, cauchy, gm or tls)");
}

double chiSquareThreshold(double confidence, int dof) {
  if (!(confidence > 0.0 && confidence < 1.0))
    throw std::invalid_argument("chiSquareThreshold: confidence must be in (0, 1), got " +
                                std::to_string(confidence));
  if (dof < 1)
    throw std::invalid_argument("chiSquareThreshold: degrees of freedom must be >= 1, got " +
                                std::to_string(dof));
  return boost::math::quantile(boost::math::chi_squared_distribution<double>(dof), confidence);
}

double RobustKernel::rho(double s) const {
  const double c2 = threshold;
  switch (kind) {
    case KernelKind::kNone:
      return s;
    case KernelKind::kHuber:
      return s <= c2 ? s : 2.0 * std::sqrt(c2 * s) - c2;
    case KernelKind::kCauchy:
      return c2 * std::log1p(s / c2);
    case KernelKind::kGemanMcClure: {
      const double m = mu * c2;
      return m * s / (m + s);
    }
    case KernelKind::kTruncatedLeastSquares: {
      if (std::isinf(mu)) return std::min(s, c2);
      if (s <= mu / (mu + 1.0) * c2) return s;
      if (s >= (mu + 1.0) / mu * c2) return c2;
      return 2.0 * std::sqrt(c2 * mu * (mu + 1.0) * s) - mu * (c2 + s);
    }
  }
  return s;
}

double RobustKernel::weight(double s) const {
  const double c2 = threshold;
  switch (kind) {
    case KernelKind::kNone:
      return 1.0;
    case KernelKind::kHuber:
      return s <= c2 ? 1.0 : std::sqrt(c2 / s);
    case KernelKind::kCauchy:
      return 1.0 / (1.0 + s / c2);
    case KernelKind::kGemanMcClure: {
      const double m = mu * c2;
      const double q = m / (m + s);
      return q * q;
    }
    case KernelKind::kTruncatedLeastSquares: {
      if (std::isinf(mu)) return s <= c2 ? 1.0 : 0.0;
      if (s <= mu / (mu + 1.0) * c2) return 1.0;
      if (s >= (mu + 1.0) / mu * c2) return 0.0;
      return std::sqrt(c2 * mu * (mu + 1.0) / s) - mu;
    }
  }
  return 1.0;
}

double RobustKernel::inlierCut() const {
  switch (kind) {
    case KernelKind::kHuber:
    case KernelKind::kCauchy:
      return weight(threshold);
    case KernelKind::kGemanMcClure:
      return gemanMcClure(threshold, 1.0).weight(threshold);
    case KernelKind::kNone:
    case KernelKind::kTruncatedLeastSquares:
      break;
  }
  return 0.5;
}

double RobustKernel::derivative(double s) const {
  const double c2 = threshold;
  switch (kind) {
    case KernelKind::kNone:
      return 0.0;
    case KernelKind::kHuber:
      return s <= c2 ? 0.0 : -0.5 * std::sqrt(c2) / (s * std::sqrt(s));
    case KernelKind::kCauchy: {
      const double q = 1.0 + s / c2;
      return -1.0 / (c2 * q * q);
    }
    case KernelKind::kGemanMcClure: {
      const double m = mu * c2;
      return -2.0 * m * m / ((m + s) * (m + s) * (m + s));
    }
    case KernelKind::kTruncatedLeastSquares: {
      if (std::isinf(mu)) return 0.0;
      if (s <= mu / (mu + 1.0) * c2 || s >= (mu + 1.0) / mu * c2) return 0.0;
      return -0.5 * std::sqrt(c2 * mu * (mu + 1.0)) / (s * std::sqrt(s));
    }
  }
  return 0.0;
}

double RobustKernel::initialMu(double s_max) const {
  switch (kind) {
    case KernelKind::kGemanMcClure:
      return std::max(1.0, 2.0 * s_max / threshold);
    case KernelKind::kTruncatedLeastSquares:
      return 2.0 * s_max > threshold ? threshold / (2.0 * s_max - threshold)
                                     : std::numeric_limits<double>::infinity();
    default:
      return mu;
  }
}

double RobustKernel::nextMu(double factor) const {
  switch (kind) {
    case KernelKind::kGemanMcClure:
      return std::max(1.0, mu / factor);
    case KernelKind::kTruncatedLeastSquares:
      return mu * factor;
    default:
      return mu;
  }
}

bool RobustKernel::atKernel() const {
  switch (kind) {
    case KernelKind::kGemanMcClure:
      return mu <= 1.0;
    case KernelKind::kTruncatedLeastSquares:
      return std::isinf(mu);
    default:
      return true;
  }
}

std::string RobustKernel::problem() const {
  if (kind == KernelKind::kNone) return "";
  if (!(threshold > 0.0) || !std::isfinite(threshold))
    return "kernel " + toString(kind) + ": threshold c² must be finite and > 0, got " +
           std::to_string(threshold);
  if (isGraduated() && !(mu > 0.0))
    return "kernel " + toString(kind) + ": GNC parameter μ must be > 0, got " + std::to_string(mu);
  return "";
}

}  // namespace arbor
