#include "arbor_slam/tools/bench/ceres_pose_graph.h"

#include <algorithm>
#include <array>
#include <chrono>
#include <set>
#include <stdexcept>
#include <utility>

#include <ceres/ceres.h>

namespace arbor::bench {
namespace {

template <typename T>
T wrap(const T& a) {
  using std::atan2, std::cos, std::sin;
  return atan2(sin(a), cos(a));
}

// 2D: parameters (x, y) and θ per pose.
struct RelativePose2Cost {
  RelativePose2Cost(const SE2& z, const Eigen::Matrix3d& sqrt_info_t)
      : z_(z), sqrt_info_t_(sqrt_info_t) {}
  template <typename T>
  bool operator()(const T* ti, const T* thi, const T* tj, const T* thj, T* residual) const {
    using std::cos, std::sin;
    const T ci = cos(*thi), si = sin(*thi);
    // m = xᵢ⁻¹xⱼ
    const T dx = tj[0] - ti[0], dy = tj[1] - ti[1];
    const T mx = ci * dx + si * dy, my = -si * dx + ci * dy;
    // δ = z⁻¹ m
    const double cz = z_.cos(), sz = z_.sin();
    const T ex = cz * (mx - z_.x()) + sz * (my - z_.y());
    const T ey = -sz * (mx - z_.x()) + cz * (my - z_.y());
    const T eth = wrap(*thj - *thi - T(z_.angle()));
    const T e[3] = {ex, ey, eth};
    for (int r = 0; r < 3; ++r) {
      residual[r] = T(0);
      for (int c = 0; c < 3; ++c) residual[r] += sqrt_info_t_(r, c) * e[c];
    }
    return true;
  }
  SE2 z_;
  Eigen::Matrix3d sqrt_info_t_;
};

// 2D pose prior: the relative-pose residual with xᵢ = I and xⱼ = x o (core/prior_factors.h).
struct PosePrior2Cost {
  PosePrior2Cost(const SE2& z, const SE2& o, const Eigen::Matrix3d& sqrt_info_t)
      : relative_(z, sqrt_info_t), o_(o) {}
  template <typename T>
  bool operator()(const T* t, const T* th, T* residual) const {
    using std::cos, std::sin;
    const T c = cos(*th), s = sin(*th);
    const T xo[2] = {t[0] + c * o_.x() - s * o_.y(), t[1] + s * o_.x() + c * o_.y()};
    const T tho = *th + T(o_.angle());
    const T zero[2] = {T(0), T(0)};
    const T zero_angle = T(0);
    return relative_(zero, &zero_angle, xo, &tho, residual);
  }
  RelativePose2Cost relative_;
  SE2 o_;
};

// Position prior: Lᵀ (t(x) − p), kDim residuals, on the translation block alone.
template <int kDim>
struct PositionPriorCost {
  using Vector = Eigen::Matrix<double, kDim, 1>;
  using Matrix = Eigen::Matrix<double, kDim, kDim>;
  PositionPriorCost(const Vector& p, const Matrix& sqrt_info_t)
      : p_(p), sqrt_info_t_(sqrt_info_t) {}
  template <typename T>
  bool operator()(const T* t, T* residual) const {
    Eigen::Map<const Eigen::Matrix<T, kDim, 1>> x(t);
    Eigen::Map<Eigen::Matrix<T, kDim, 1>> r(residual);
    r = sqrt_info_t_.template cast<T>() * (x - p_.template cast<T>());
    return true;
  }
  Vector p_;
  Matrix sqrt_info_t_;
};

// 3D: parameters t (3) and an Eigen quaternion (x, y, z, w) per pose.
struct RelativePose3Cost {
  RelativePose3Cost(const SE3& z, const Eigen::Matrix<double, 6, 6>& sqrt_info_t)
      : z_(z), sqrt_info_t_(sqrt_info_t) {}
  template <typename T>
  bool operator()(const T* ti_p, const T* qi_p, const T* tj_p, const T* qj_p, T* residual) const {
    Eigen::Map<const Eigen::Matrix<T, 3, 1>> ti(ti_p), tj(tj_p);
    Eigen::Map<const Eigen::Quaternion<T>> qi(qi_p), qj(qj_p);
    const Eigen::Quaternion<T> qi_inv = qi.conjugate();
    const Eigen::Matrix<T, 3, 1> tm = qi_inv * (tj - ti);
    const Eigen::Quaternion<T> qm = qi_inv * qj;
    const Eigen::Quaternion<T> qz_inv = z_.quaternion().conjugate().template cast<T>();
    const Eigen::Matrix<T, 3, 1> td = qz_inv * (tm - z_.translation().template cast<T>());
    Eigen::Quaternion<T> qd = qz_inv * qm;
    if (qd.w() < T(0)) qd.coeffs() = -qd.coeffs();
    Eigen::Matrix<T, 6, 1> e;
    e << td, T(2) * qd.vec();
    Eigen::Map<Eigen::Matrix<T, 6, 1>> r(residual);
    r = sqrt_info_t_.template cast<T>() * e;
    return true;
  }
  SE3 z_;
  Eigen::Matrix<double, 6, 6> sqrt_info_t_;
};

// 3D pose prior: the relative-pose residual with xᵢ = I and xⱼ = x o.
struct PosePrior3Cost {
  PosePrior3Cost(const SE3& z, const SE3& o, const Eigen::Matrix<double, 6, 6>& sqrt_info_t)
      : relative_(z, sqrt_info_t), o_(o) {}
  template <typename T>
  bool operator()(const T* t_p, const T* q_p, T* residual) const {
    Eigen::Map<const Eigen::Matrix<T, 3, 1>> t(t_p);
    Eigen::Map<const Eigen::Quaternion<T>> q(q_p);
    const Eigen::Matrix<T, 3, 1> to = t + q * o_.translation().template cast<T>();
    const Eigen::Quaternion<T> qo = q * o_.quaternion().template cast<T>();
    const T zero_t[3] = {T(0), T(0), T(0)};
    const T identity_q[4] = {T(0), T(0), T(0), T(1)};
    return relative_(zero_t, identity_q, to.data(), qo.coeffs().data(), residual);
  }
  RelativePose3Cost relative_;
  SE3 o_;
};

ceres::Solver::Options paperOptions(int max_iterations, double function_tolerance) {
  ceres::Solver::Options o;
  o.minimizer_type = ceres::TRUST_REGION;
  o.trust_region_strategy_type = ceres::LEVENBERG_MARQUARDT;
  o.linear_solver_type = ceres::SPARSE_NORMAL_CHOLESKY;
  o.max_num_iterations = max_iterations;
  o.function_tolerance = function_tolerance;
  o.num_threads = 1;
  o.logging_type = ceres::SILENT;
  return o;
}

CeresResult toResult(const ceres::Solver::Summary& s) {
  CeresResult r;
  r.F_initial = 2.0 * s.initial_cost;
  r.F_final = 2.0 * s.final_cost;
  r.iterations = static_cast<int>(s.iterations.size()) - 1;
  r.termination = ceres::TerminationTypeToString(s.termination_type);
  r.time_s = s.total_time_in_seconds;
  return r;
}

}  // namespace

namespace {

// The 2D problem over t (2 per pose) and th (1 per pose), the gauge poses `fixed` constant.
void add2D(const PoseGraph<SE2>& graph, const std::vector<int>& fixed, std::vector<double>* t_p,
           std::vector<double>* th_p, ceres::Problem* problem_p) {
  std::vector<double>& t = *t_p;
  std::vector<double>& th = *th_p;
  ceres::Problem& problem = *problem_p;
  for (const auto& e : graph.edges) {
    auto* cost = new ceres::AutoDiffCostFunction<RelativePose2Cost, 3, 2, 1, 2, 1>(
        new RelativePose2Cost(e.measurement, e.sqrt_information_t));
    problem.AddResidualBlock(cost, nullptr, &t[2 * e.i], &th[e.i], &t[2 * e.j], &th[e.j]);
  }
  for (const auto& p : graph.pose_priors) {
    auto* cost = new ceres::AutoDiffCostFunction<PosePrior2Cost, 3, 2, 1>(
        new PosePrior2Cost(p.measurement, p.offset, p.sqrt_information_t));
    problem.AddResidualBlock(cost, nullptr, &t[2 * p.i], &th[p.i]);
  }
  for (const auto& p : graph.position_priors) {
    auto* cost = new ceres::AutoDiffCostFunction<PositionPriorCost<2>, 2, 2>(
        new PositionPriorCost<2>(p.position, p.sqrt_information_t));
    problem.AddResidualBlock(cost, nullptr, &t[2 * p.i]);
  }
  for (int g : fixed) {  // a gauge pose without factors is no block of Ceres'
    if (problem.HasParameterBlock(&t[2 * g])) problem.SetParameterBlockConstant(&t[2 * g]);
    if (problem.HasParameterBlock(&th[g])) problem.SetParameterBlockConstant(&th[g]);
  }
}

// Ceres' parameters of the 2D poses: t (x, y per pose) and th (θ per pose).
void pack2D(const std::vector<SE2>& poses, std::vector<double>* t, std::vector<double>* th) {
  const size_t n = poses.size();
  t->resize(2 * n);
  th->resize(n);
  for (size_t k = 0; k < n; ++k) {
    (*t)[2 * k] = poses[k].x();
    (*t)[2 * k + 1] = poses[k].y();
    (*th)[k] = poses[k].angle();
  }
}

}  // namespace

template <>
CeresResult solveWithCeres(const PoseGraph<SE2>& graph, std::vector<SE2>* poses, int max_iterations,
                           double function_tolerance) {
  const int n = graph.numPoses();
  std::vector<double> t, th;
  pack2D(*poses, &t, &th);
  ceres::Problem problem;
  add2D(graph, graph.gaugeIndices(), &t, &th, &problem);
  ceres::Solver::Summary summary;
  ceres::Solve(paperOptions(max_iterations, function_tolerance), &problem, &summary);
  for (int k = 0; k < n; ++k) (*poses)[k] = SE2(t[2 * k], t[2 * k + 1], th[k]);
  return toResult(summary);
}

std::vector<Eigen::Matrix3d> ceresCovariances(const PoseGraph<SE2>& graph,
                                              const std::vector<SE2>& poses,
                                              const std::vector<int>& fixed, double* time_s) {
  const int n = graph.numPoses();
  std::vector<double> t, th;
  pack2D(poses, &t, &th);
  ceres::Problem problem;
  add2D(graph, fixed, &t, &th, &problem);
  std::vector<char> is_fixed(n, 0);
  for (int g : fixed) is_fixed[g] = 1;
  std::vector<std::pair<const double*, const double*>> blocks;
  for (int k = 0; k < n; ++k) {
    if (is_fixed[k]) continue;
    blocks.emplace_back(&t[2 * k], &t[2 * k]);
    blocks.emplace_back(&t[2 * k], &th[k]);
    blocks.emplace_back(&th[k], &th[k]);
  }
  const auto t0 = std::chrono::steady_clock::now();
  ceres::Covariance::Options options;
  options.num_threads = 1;
  ceres::Covariance covariance(options);
  if (!covariance.Compute(blocks, &problem))
    throw std::runtime_error("ceres::Covariance::Compute failed");
  std::vector<Eigen::Matrix3d> out(n, Eigen::Matrix3d::Zero());
  for (int k = 0; k < n; ++k) {
    if (is_fixed[k]) continue;
    double tt[4], tth[2], thth[1];
    covariance.GetCovarianceBlock(&t[2 * k], &t[2 * k], tt);
    covariance.GetCovarianceBlock(&t[2 * k], &th[k], tth);
    covariance.GetCovarianceBlock(&th[k], &th[k], thth);
    Eigen::Matrix3d world;  // of (t, θ), row-major blocks
    world << tt[0], tt[1], tth[0], tt[2], tt[3], tth[1], tth[0], tth[1], thth[0];
    Eigen::Matrix3d J = Eigen::Matrix3d::Identity();
    J.topLeftCorner<2, 2>() = poses[k].rotation().transpose();
    out[k] = J * world * J.transpose();
  }
  *time_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return out;
}

std::vector<Eigen::Matrix<double, 6, 6>> ceresJointCovariances(
    const PoseGraph<SE2>& graph, const std::vector<SE2>& poses, const std::vector<int>& fixed,
    const std::vector<std::pair<int, int>>& pairs) {
  std::vector<double> t, th;
  pack2D(poses, &t, &th);
  ceres::Problem problem;
  add2D(graph, fixed, &t, &th, &problem);
  // Each pose's parameter blocks (t, θ) and their sizes; the pairs' blocks, each once (Ceres
  // refuses duplicates, (x, y) and (y, x) alike).
  auto params = [&](int k) {
    return std::array<std::pair<const double*, int>, 2>{{{&t[2 * k], 2}, {&th[k], 1}}};
  };
  std::set<std::pair<const double*, const double*>> wanted;
  for (const auto& [a, b] : pairs)
    for (int u : {a, b})
      for (int w : {a, b})
        for (const auto& x : params(u))
          for (const auto& y : params(w))
            wanted.emplace(std::min(x.first, y.first), std::max(x.first, y.first));
  const std::vector<std::pair<const double*, const double*>> blocks(wanted.begin(), wanted.end());
  ceres::Covariance::Options options;
  options.num_threads = 1;
  ceres::Covariance covariance(options);
  if (!covariance.Compute(blocks, &problem))
    throw std::runtime_error("ceres::Covariance::Compute failed");
  std::vector<Eigen::Matrix<double, 6, 6>> out;
  for (const auto& [a, b] : pairs) {
    // Of (t_a, θ_a, t_b, θ_b) in the world frame, then J = diag(R_aᵀ, 1, R_bᵀ, 1).
    Eigen::Matrix<double, 6, 6> world;
    const int pose[2] = {a, b};
    for (int i = 0; i < 2; ++i)
      for (int j = 0; j < 2; ++j) {
        int row = 3 * i;
        for (const auto& x : params(pose[i])) {
          int col = 3 * j;
          for (const auto& y : params(pose[j])) {
            Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> block(x.second,
                                                                                         y.second);
            covariance.GetCovarianceBlock(x.first, y.first, block.data());
            world.block(row, col, x.second, y.second) = block;
            col += y.second;
          }
          row += x.second;
        }
      }
    Eigen::Matrix<double, 6, 6> J = Eigen::Matrix<double, 6, 6>::Identity();
    J.block<2, 2>(0, 0) = poses[a].rotation().transpose();
    J.block<2, 2>(3, 3) = poses[b].rotation().transpose();
    out.push_back(J * world * J.transpose());
  }
  return out;
}

template <>
CeresResult solveWithCeres(const PoseGraph<SE3>& graph, std::vector<SE3>* poses, int max_iterations,
                           double function_tolerance) {
  const int n = graph.numPoses();
  std::vector<double> t(3 * n), q(4 * n);
  for (int k = 0; k < n; ++k) {
    Eigen::Map<Eigen::Vector3d> tk(&t[3 * k]);
    Eigen::Map<Eigen::Vector4d> qk(&q[4 * k]);
    tk = (*poses)[k].translation();
    qk = (*poses)[k].quaternion().coeffs();
  }
  ceres::Problem problem;
  for (const auto& e : graph.edges) {
    auto* cost = new ceres::AutoDiffCostFunction<RelativePose3Cost, 6, 3, 4, 3, 4>(
        new RelativePose3Cost(e.measurement, e.sqrt_information_t));
    problem.AddResidualBlock(cost, nullptr, &t[3 * e.i], &q[4 * e.i], &t[3 * e.j], &q[4 * e.j]);
  }
  for (const auto& p : graph.pose_priors) {
    auto* cost = new ceres::AutoDiffCostFunction<PosePrior3Cost, 6, 3, 4>(
        new PosePrior3Cost(p.measurement, p.offset, p.sqrt_information_t));
    problem.AddResidualBlock(cost, nullptr, &t[3 * p.i], &q[4 * p.i]);
  }
  for (const auto& p : graph.position_priors) {
    auto* cost = new ceres::AutoDiffCostFunction<PositionPriorCost<3>, 3, 3>(
        new PositionPriorCost<3>(p.position, p.sqrt_information_t));
    problem.AddResidualBlock(cost, nullptr, &t[3 * p.i]);
  }
  for (int k = 0; k < n; ++k) {
    if (problem.HasParameterBlock(&q[4 * k])) {
      problem.SetManifold(&q[4 * k], new ceres::EigenQuaternionManifold);
    }
  }
  for (int g : graph.gaugeIndices()) {  // a gauge pose without factors is no block of Ceres'
    if (problem.HasParameterBlock(&t[3 * g])) problem.SetParameterBlockConstant(&t[3 * g]);
    if (problem.HasParameterBlock(&q[4 * g])) problem.SetParameterBlockConstant(&q[4 * g]);
  }
  ceres::Solver::Summary summary;
  ceres::Solve(paperOptions(max_iterations, function_tolerance), &problem, &summary);
  for (int k = 0; k < n; ++k) {
    const Eigen::Vector4d c = Eigen::Map<Eigen::Vector4d>(&q[4 * k]);
    (*poses)[k] =
        SE3(Eigen::Quaterniond(c(3), c(0), c(1), c(2)), Eigen::Map<Eigen::Vector3d>(&t[3 * k]));
  }
  return toResult(summary);
}

}  // namespace arbor::bench
