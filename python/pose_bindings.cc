// arbor_slam.SE2 and arbor_slam.SE3: the pose types of core/se2.h and core/se3.h with numpy in and
// out: composition, inverse, between, Log/Exp (tangent [translation; rotation], the C++ order),
// homogeneous matrices, a tolerance comparison and pickling.
#include <cmath>
#include <string>

#include <pybind11/eigen.h>
#include <pybind11/operators.h>
#include <pybind11/pybind11.h>

#include "bindings.h"
#include "conversions.h"

namespace arbor::python {
namespace {

/// A tangent vector of k finite numbers, or ValueError naming `what`.
template <class G>
typename G::Tangent tangentFromArray(const Eigen::VectorXd& v, const char* what) {
  if (v.size() != G::kDoF || !v.allFinite())
    throw std::invalid_argument(std::string(what) + ": expected " + std::to_string(G::kDoF) +
                                " finite numbers [translation; rotation], got " +
                                std::to_string(v.size()) + (v.allFinite() ? "" : " not finite"));
  return v;
}

/// The homogeneous (d+1)×(d+1) matrix of a pose.
template <class G>
Eigen::MatrixXd homogeneous(const G& x) {
  constexpr int d = G::kDim;
  Eigen::MatrixXd m = Eigen::MatrixXd::Identity(d + 1, d + 1);
  m.topLeftCorner(d, d) = x.rotation();
  m.topRightCorner(d, 1) = x.translation();
  return m;
}

/// Checks a homogeneous matrix: shape, finite, last row [0 … 0 1], R orthonormal with det +1
/// (to 1e-6). Returns R (re-orthonormalised by the pose's own constructor later).
template <int D>
Eigen::Matrix<double, D, D> rotationOfMatrix(const Eigen::MatrixXd& m) {
  if (m.rows() != D + 1 || m.cols() != D + 1)
    throw std::invalid_argument("matrix: expected " + std::to_string(D + 1) + "x" +
                                std::to_string(D + 1) + ", got " + std::to_string(m.rows()) + "x" +
                                std::to_string(m.cols()));
  if (!m.allFinite()) throw std::invalid_argument("matrix: not every entry is finite");
  Eigen::Matrix<double, 1, D + 1> last = Eigen::Matrix<double, 1, D + 1>::Zero();
  last(D) = 1.0;
  if ((m.row(D) - last).cwiseAbs().maxCoeff() > 1e-12)
    throw std::invalid_argument("matrix: the last row is not [0 ... 0 1]");
  const Eigen::Matrix<double, D, D> r = m.topLeftCorner(D, D);
  const double off = (r.transpose() * r - Eigen::Matrix<double, D, D>::Identity()).norm();
  if (off > 1e-6 || r.determinant() < 0)
    throw std::invalid_argument(
        "matrix: the rotation block is not a rotation (|RᵀR − I| = " + std::to_string(off) +
        ", det " + std::to_string(r.determinant()) + ")");
  return r;
}

/// The methods SE2 and SE3 share.
template <class G, class Class>
void defineCommon(Class& c) {
  constexpr int k = G::kDoF;
  c.def(
       "compose", [](const G& a, const G& b) { return a.compose(b); }, py::arg("other"),
       "self · other (also `self * other`): the pose `other`, given in the frame of self, in "
       "the world frame.")
      .def(
          "__mul__", [](const G& a, const G& b) { return a.compose(b); }, py::is_operator())
      .def(
          "inverse", [](const G& a) { return a.inverse(); }, "self⁻¹.")
      .def(
          "between", [](const G& a, const G& b) { return a.between(b); }, py::arg("other"),
          "self⁻¹ · other: other in the frame of self (what a relative-pose edge from self to "
          "other measures).")
      .def(
          "log", [](const G& a) { return Eigen::VectorXd(a.Log()); },
          k == 3 ? "The tangent vector [vx, vy, θ] with exp(log()) = self."
                 : "The tangent vector [ρ (3); θ (3)] with exp(log()) = self.")
      .def_static(
          "exp", [](const Eigen::VectorXd& v) { return G::Exp(tangentFromArray<G>(v, "exp")); },
          py::arg("tangent"),
          "The group exponential of a tangent vector [translation; rotation] (the C++ order).")
      .def(
          "matrix", [](const G& a) { return homogeneous(a); },
          "The homogeneous matrix [[R, t], [0, 1]] (3x3 in 2D, 4x4 in 3D).")
      .def(
          "translation", [](const G& a) { return Eigen::VectorXd(a.translation()); },
          "The translation t as a numpy vector.")
      .def(
          "rotation", [](const G& a) { return Eigen::MatrixXd(a.rotation()); },
          "The rotation matrix R (2x2 in 2D, 3x3 in 3D).")
      .def(
          "to_array", [](const G& a) { return poseToArray(a); },
          k == 3 ? "The row [x, y, θ] (the order of Graph2.poses and the estimates)."
                 : "The row [x, y, z, qx, qy, qz, qw] (the g2o and TUM order of Graph3.poses "
                   "and the estimates).")
      .def_static(
          "from_array", [](const Eigen::VectorXd& v) { return poseFromArray<G>(v, "pose"); },
          py::arg("row"), "The inverse of to_array().")
      .def_static(
          "identity", [] { return G::Identity(); }, "The identity pose.")
      .def(
          "isclose",
          [](const G& a, const G& b, double atol) {
            return (homogeneous(a) - homogeneous(b)).cwiseAbs().maxCoeff() <= atol;
          },
          py::arg("other"), py::arg("atol") = 1e-9,
          "True when every entry of the two homogeneous matrices differs by at most atol.")
      .def("__copy__", [](const G& a) { return a; })
      .def(
          "__deepcopy__", [](const G& a, const py::dict&) { return a; }, py::arg("memo"));
}

void defineSE2(py::module_& m) {
  py::class_<SE2> c(m, "SE2",
                    "A planar rigid motion (rotation by θ, then translation (x, y)); core/se2.h.");
  c.def(py::init([](double x, double y, double theta) {
          if (!std::isfinite(x) || !std::isfinite(y) || !std::isfinite(theta))
            throw std::invalid_argument("SE2(x, y, theta): every value must be finite");
          return SE2(x, y, theta);
        }),
        py::arg("x") = 0.0, py::arg("y") = 0.0, py::arg("theta") = 0.0,
        "SE2(x, y, theta): translation (x, y), rotation θ in radians.")
      .def_static(
          "from_matrix",
          [](const Eigen::MatrixXd& m) {
            const Eigen::Matrix2d r = rotationOfMatrix<2>(m);
            return SE2(m(0, 2), m(1, 2), std::atan2(r(1, 0), r(0, 0)));
          },
          py::arg("matrix"), "The pose of a 3x3 homogeneous matrix (checked: a rotation block).")
      .def_property_readonly("x", &SE2::x, "translation x")
      .def_property_readonly("y", &SE2::y, "translation y")
      .def_property_readonly("theta", &SE2::angle, "rotation angle in (−π, π]")
      .def("__repr__",
           [](const SE2& a) {
             return py::str("SE2(x={!r}, y={!r}, theta={!r})")
                 .format(a.x(), a.y(), a.angle())
                 .cast<std::string>();
           })
      .def(py::pickle([](const SE2& a) { return py::make_tuple(a.x(), a.y(), a.angle()); },
                      [](const py::tuple& t) {
                        if (t.size() != 3) throw std::invalid_argument("SE2: bad pickle state");
                        return SE2(t[0].cast<double>(), t[1].cast<double>(), t[2].cast<double>());
                      }));
  defineCommon<SE2>(c);
}

void defineSE3(py::module_& m) {
  py::class_<SE3> c(m, "SE3",
                    "A rigid motion in space (rotation by a unit quaternion, then translation); "
                    "core/se3.h.");
  c.def(py::init([](const Eigen::VectorXd& t, const Eigen::VectorXd& q) {
          if (t.size() != 3 || !t.allFinite())
            throw std::invalid_argument("SE3: translation must be 3 finite numbers");
          if (q.size() != 4 || !q.allFinite())
            throw std::invalid_argument("SE3: quaternion must be 4 finite numbers (w, x, y, z)");
          Eigen::VectorXd row(7);
          row << t, q(1), q(2), q(3), q(0);
          return poseFromArray<SE3>(row, "SE3");
        }),
        py::arg("translation") = Eigen::Vector3d::Zero().eval(),
        py::arg("quaternion") = Eigen::Vector4d(1, 0, 0, 0).eval(),
        "SE3(translation, quaternion): translation [x, y, z] and the unit quaternion in the "
        "order (w, x, y, z) (norm 1 within 1e-6; it is renormalised).")
      .def_static(
          "from_matrix",
          [](const Eigen::MatrixXd& m) {
            const Eigen::Matrix3d r = rotationOfMatrix<3>(m);
            return SE3(Eigen::Quaterniond(r).normalized(), Eigen::Vector3d(m.topRightCorner(3, 1)));
          },
          py::arg("matrix"), "The pose of a 4x4 homogeneous matrix (checked: a rotation block).")
      .def(
          "quaternion",
          [](const SE3& a) {
            const Eigen::Quaterniond& q = a.quaternion();
            return Eigen::Vector4d(q.w(), q.x(), q.y(), q.z());
          },
          "The rotation as the unit quaternion (w, x, y, z).")
      .def("__repr__",
           [](const SE3& a) {
             const Eigen::Vector3d& t = a.translation();
             const Eigen::Quaterniond& q = a.quaternion();
             return py::str(
                        "SE3(translation=[{!r}, {!r}, {!r}], quaternion=[{!r}, {!r}, {!r}, {!r}])")
                 .format(t.x(), t.y(), t.z(), q.w(), q.x(), q.y(), q.z())
                 .cast<std::string>();
           })
      .def(py::pickle(
          [](const SE3& a) {
            const Eigen::Vector3d& t = a.translation();
            const Eigen::Quaterniond& q = a.quaternion();
            return py::make_tuple(t.x(), t.y(), t.z(), q.w(), q.x(), q.y(), q.z());
          },
          [](const py::tuple& s) {
            if (s.size() != 7) throw std::invalid_argument("SE3: bad pickle state");
            double v[7];
            for (int i = 0; i < 7; ++i) v[i] = s[i].cast<double>();
            // The stored quaternion, unit already (the constructor normalises it again).
            return SE3(Eigen::Quaterniond(v[3], v[4], v[5], v[6]),
                       Eigen::Vector3d(v[0], v[1], v[2]));
          }));
  defineCommon<SE3>(c);
}

}  // namespace

void definePoses(py::module_& m) {
  defineSE2(m);
  defineSE3(m);
}

}  // namespace arbor::python
