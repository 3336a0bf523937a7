// Poses, measurements and matrices between numpy and Arbor: SE(2) as a row [x y θ], SE(3) as a
// row [x y z qx qy qz qw] (the g2o and TUM order); a set of n poses as an n×3 or n×7 array;
// information and covariance matrices as k×k arrays (k = 3 in 2D, 6 in 3D, tangent order
// [translation; rotation]). Every check throws std::invalid_argument (Python's ValueError)
// naming what was wrong.
#pragma once

#include <cmath>
#include <string>
#include <vector>

#include <pybind11/eigen.h>
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <Eigen/Core>
#include <Eigen/Geometry>

#include "arbor_slam/core/pose_graph.h"
#include "arbor_slam/core/se2.h"
#include "arbor_slam/core/se3.h"

namespace arbor::python {

namespace py = pybind11;

/// Columns of one pose row: 3 for SE2, 7 for SE3.
template <class G>
constexpr int poseColumns() {
  return G::kDim == 2 ? 3 : 7;
}

/// Row-major n×c matrix of doubles (numpy's default layout).
using RowMatrix = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;

inline SE2 poseFromRow(const double* r, SE2*) { return SE2(r[0], r[1], r[2]); }
inline SE3 poseFromRow(const double* r, SE3*) {
  // Eigen's Quaterniond(w, x, y, z); the row has x y z w.
  return SE3(Eigen::Quaterniond(r[6], r[3], r[4], r[5]), Eigen::Vector3d(r[0], r[1], r[2]));
}
inline void poseToRow(const SE2& x, double* r) {
  r[0] = x.x();
  r[1] = x.y();
  r[2] = x.angle();
}
inline void poseToRow(const SE3& x, double* r) {
  const Eigen::Vector3d& t = x.translation();
  const Eigen::Quaterniond& q = x.quaternion();
  r[0] = t.x();
  r[1] = t.y();
  r[2] = t.z();
  r[3] = q.x();
  r[4] = q.y();
  r[5] = q.z();
  r[6] = q.w();
}

/// One pose from a sequence of 3 (SE2) or 7 (SE3) finite numbers; an SE3 quaternion must have a
/// norm within 1e-6 of 1 (it is then renormalised). `what` names the argument in messages.
template <class G>
G poseFromArray(const Eigen::VectorXd& v, const std::string& what) {
  constexpr int c = poseColumns<G>();
  if (v.size() != c)
    throw std::invalid_argument(what + ": expected " + std::to_string(c) + " numbers (" +
                                (c == 3 ? "x y theta" : "x y z qx qy qz qw") + "), got " +
                                std::to_string(v.size()));
  for (int k = 0; k < c; ++k)
    if (!std::isfinite(v[k]))
      throw std::invalid_argument(what + ": entry " + std::to_string(k) + " is not finite");
  if constexpr (c == 7) {
    const double norm = v.tail<4>().norm();
    if (std::abs(norm - 1.0) > 1e-6)
      throw std::invalid_argument(what + ": quaternion norm " + std::to_string(norm) + " is not 1");
  }
  return poseFromRow(v.data(), static_cast<G*>(nullptr));
}

template <class G>
Eigen::VectorXd poseToArray(const G& x) {
  Eigen::VectorXd v(poseColumns<G>());
  poseToRow(x, v.data());
  return v;
}

template <class G>
RowMatrix posesToArray(const std::vector<G>& poses) {
  RowMatrix out(static_cast<Eigen::Index>(poses.size()), poseColumns<G>());
  for (size_t k = 0; k < poses.size(); ++k) poseToRow(poses[k], out.row(k).data());
  return out;
}

/// n poses from an n×3 or n×7 array (each row checked as poseFromArray).
template <class G>
std::vector<G> posesFromArray(const RowMatrix& a, int n, const std::string& what) {
  if (a.rows() != n || a.cols() != poseColumns<G>())
    throw std::invalid_argument(what + ": expected a " + std::to_string(n) + "x" +
                                std::to_string(poseColumns<G>()) + " array, got " +
                                std::to_string(a.rows()) + "x" + std::to_string(a.cols()));
  std::vector<G> poses;
  poses.reserve(n);
  for (int k = 0; k < n; ++k)
    poses.push_back(poseFromArray<G>(a.row(k).transpose(), what + " row " + std::to_string(k)));
  return poses;
}

/// A k×k matrix (information) from an array, checked for shape and finiteness.
template <int K>
Eigen::Matrix<double, K, K> squareFromArray(const Eigen::MatrixXd& m, const std::string& what) {
  if (m.rows() != K || m.cols() != K)
    throw std::invalid_argument(what + ": expected a " + std::to_string(K) + "x" +
                                std::to_string(K) + " matrix, got " + std::to_string(m.rows()) +
                                "x" + std::to_string(m.cols()));
  if (!m.allFinite()) throw std::invalid_argument(what + ": not every entry is finite");
  return m;
}

/// Ids of a graph as an int64 array.
inline py::array_t<std::int64_t> idsToArray(const std::vector<Key>& ids) {
  py::array_t<std::int64_t> out(static_cast<py::ssize_t>(ids.size()));
  auto w = out.mutable_unchecked<1>();
  for (size_t k = 0; k < ids.size(); ++k) w(k) = ids[k];
  return out;
}

}  // namespace arbor::python
