// arbor_slam.CustomFactor2 / CustomFactor3: factors of your own in Python (custom_factor_object.h,
// docs/python.md "Factors of your own").
#include <cmath>
#include <stdexcept>
#include <string>
#include <utility>

#include <pybind11/eigen.h>
#include <pybind11/numpy.h>
#include <pybind11/stl.h>

#include "bindings.h"
#include "custom_factor_object.h"

namespace arbor::python {

namespace py = pybind11;

template <class G>
PyFactorModel<G>::PyFactorModel(py::object error, py::object jacobian, int rows, int arity,
                                std::string name, double step)
    : error_(std::move(error)),
      jacobian_(std::move(jacobian)),
      rows_(rows),
      arity_(arity),
      name_(std::move(name)),
      step_(step) {}

template <class G>
PyFactorModel<G>::~PyFactorModel() {
  // The last copy of a factor may go away on a thread without the GIL (a solver's copy of the
  // graph); the Python references are dropped under it, or leaked when Python has shut down.
  if (!Py_IsInitialized()) {
    error_.release();
    jacobian_.release();
    return;
  }
  py::gil_scoped_acquire gil;
  error_ = py::object();
  jacobian_ = py::object();
}

namespace {

/// A numpy array (or anything numpy takes) of `rows`×`cols` finite numbers (cols 0: a vector of
/// `rows`, a scalar accepted when rows is 1); `what` names it in the error.
Eigen::MatrixXd numbersOf(const py::handle& h, int rows, int cols, const std::string& what) {
  py::array_t<double, py::array::c_style | py::array::forcecast> a;
  try {
    a = py::array_t<double, py::array::c_style | py::array::forcecast>::ensure(h);
  } catch (const py::error_already_set&) {
    a = {};
  }
  if (!a)
    throw py::type_error(what + ": expected numbers, got " + std::string(py::str(h.get_type())));
  const bool vector = cols == 0;
  const py::ssize_t r = a.ndim() == 0 ? 1 : a.shape(0);
  const py::ssize_t c = a.ndim() < 2 ? (vector ? 0 : 1) : a.shape(1);
  const bool fits =
      vector ? (a.ndim() <= 1 && a.size() == rows) : (a.ndim() == 2 && r == rows && c == cols);
  if (!fits) {
    std::string shape;
    for (py::ssize_t k = 0; k < a.ndim(); ++k) shape += (k ? "x" : "") + std::to_string(a.shape(k));
    throw std::invalid_argument(what + ": expected " + std::to_string(rows) +
                                (vector ? " entries" : "x" + std::to_string(cols)) +
                                ", got shape (" + shape + ")");
  }
  Eigen::MatrixXd m(rows, vector ? 1 : cols);
  const double* p = a.data();
  for (int i = 0; i < m.rows(); ++i)
    for (int j = 0; j < m.cols(); ++j) m(i, j) = p[i * m.cols() + j];
  if (!m.allFinite()) throw std::invalid_argument(what + ": not every entry is finite");
  return m;
}

}  // namespace

template <class G>
typename PyFactorModel<G>::Residual PyFactorModel<G>::callError(const py::tuple& poses) const {
  const py::object r = error_(*poses);
  return numbersOf(r, rows_, 0, "custom factor '" + name_ + "': error()");
}

template <class G>
void PyFactorModel<G>::evaluate(const std::array<const G*, 2>& x, Residual* e, Jacobians* J) const {
  constexpr int k = G::kDoF;
  py::gil_scoped_acquire gil;
  py::tuple poses(arity_);
  for (int a = 0; a < arity_; ++a) poses[a] = py::cast(*x[static_cast<size_t>(a)]);
  *e = callError(poses);
  if (!J) return;
  if (!jacobian_.is_none()) {
    const std::string what = "custom factor '" + name_ + "': jacobian()";
    const py::object r = jacobian_(*poses);
    // One matrix for a unary factor, else a sequence of arity matrices.
    const bool single = arity_ == 1 && py::isinstance<py::array>(r);
    if (!single && (!py::isinstance<py::sequence>(r) || py::len(r) != static_cast<size_t>(arity_)))
      throw std::invalid_argument(what + ": expected a list of " + std::to_string(arity_) +
                                  " matrices of " + std::to_string(rows_) + "x" +
                                  std::to_string(k));
    for (int a = 0; a < arity_; ++a) {
      const py::object m = single ? r : py::reinterpret_borrow<py::sequence>(r)[a];
      (*J)[static_cast<size_t>(a)] = numbersOf(m, rows_, k, what + " matrix " + std::to_string(a));
    }
    return;
  }
  // Central differences through x ⊞ τ, one pose and one direction at a time.
  for (int a = 0; a < arity_; ++a) {
    auto& Ja = (*J)[static_cast<size_t>(a)];
    Ja.resize(rows_, k);
    const G& xa = *x[static_cast<size_t>(a)];
    for (int d = 0; d < k; ++d) {
      typename G::Tangent tau = G::Tangent::Zero();
      tau[d] = step_;
      py::tuple plus(arity_), minus(arity_);
      for (int b = 0; b < arity_; ++b) {
        plus[b] = poses[b];
        minus[b] = poses[b];
      }
      plus[a] = py::cast(xa.retract(tau));
      minus[a] = py::cast(xa.retract(-tau));
      Ja.col(d) = (callError(plus) - callError(minus)) / (2 * step_);
    }
  }
}

bool raiseCause(const FactorError& error) {
  // The innermost cause (a FactorError may nest another, the online layer's around the
  // smoother's).
  std::exception_ptr cause;
  try {
    std::rethrow_if_nested(error);
  } catch (...) {
    cause = std::current_exception();
  }
  for (bool deeper = cause != nullptr; deeper;) {
    deeper = false;
    try {
      std::rethrow_exception(cause);
    } catch (const std::nested_exception& n) {
      if (n.nested_ptr()) {
        cause = n.nested_ptr();
        deeper = true;
      }
    } catch (...) {
    }
  }
  if (!cause) return false;
  try {
    std::rethrow_exception(cause);
  } catch (py::error_already_set& e) {
    e.restore();
  } catch (const py::builtin_exception& e) {
    e.set_error();
  } catch (...) {
    return false;
  }
  // PEP 678 (Python 3.11): the note names the factor; older Pythons get the exception alone.
  PyObject *type = nullptr, *value = nullptr, *trace = nullptr;
  PyErr_Fetch(&type, &value, &trace);
  PyErr_NormalizeException(&type, &value, &trace);
  // The note without pybind11's "\n\nAt:" traceback of the cause (Python shows its own).
  std::string note = error.what();
  const size_t at = note.find("\n\nAt:");
  if (at != std::string::npos) note.resize(at);
  if (value != nullptr && PyObject_HasAttrString(value, "add_note")) {
    PyObject* r = PyObject_CallMethod(value, "add_note", "s", note.c_str());
    if (r == nullptr) PyErr_Clear();
    Py_XDECREF(r);
  }
  if (trace != nullptr && value != nullptr) PyException_SetTraceback(value, trace);
  PyErr_Restore(type, value, trace);
  return true;
}

template class PyFactorModel<SE2>;
template class PyFactorModel<SE3>;

namespace {

template <class G>
void defineCustomFactorOf(py::module_& m, const char* name) {
  using Object = CustomFactorObject<G>;
  constexpr int k = G::kDoF;
  const std::string pose = G::kDim == 2 ? "SE2" : "SE3";
  py::class_<Object>(m, name,
                     ("A factor of your own on one or two " + pose +
                      " poses whose error (and optionally Jacobians) are Python functions "
                      "(docs/python.md, \"Factors of your own\").")
                         .c_str())
      .def(
          py::init([name](const py::object& keys, const py::function& error,
                          const Eigen::MatrixXd& information, const py::object& jacobian,
                          const std::string& factor_name, double step) {
            const std::string what = std::string(name) + " '" + factor_name + "'";
            Object o;
            if (py::isinstance<py::int_>(keys)) {
              o.keys.push_back(keys.cast<Key>());
            } else {
              try {
                o.keys = keys.cast<std::vector<Key>>();
              } catch (const py::cast_error&) {
                throw py::type_error(what + ": keys: expected a pose id or a list of 1 or 2");
              }
            }
            if (o.keys.size() != 1 && o.keys.size() != 2)
              throw std::invalid_argument(what + ": keys: expected 1 or 2 pose ids, got " +
                                          std::to_string(o.keys.size()));
            if (o.keys.size() == 2 && o.keys[0] == o.keys[1])
              throw std::invalid_argument(what + ": keys: both are pose " +
                                          std::to_string(o.keys[0]));
            if (!jacobian.is_none() && !PyCallable_Check(jacobian.ptr()))
              throw py::type_error(what + ": jacobian: expected a function or None");
            if (!(step > 0) || !std::isfinite(step))
              throw std::invalid_argument(what + ": step must be > 0, not " + std::to_string(step));
            const int arity = static_cast<int>(o.keys.size());
            const int rows = static_cast<int>(information.rows());
            o.model =
                std::make_shared<PyFactorModel<G>>(error, jacobian, rows, arity, factor_name, step);
            o.information = information;
            o.make(0, arity == 2 ? 1 : -1);  // Ω and rows checked now, by the library
            return o;
          }),
          py::arg("keys"), py::arg("error"), py::arg("information"),
          py::arg("jacobian") = py::none(), py::arg("name") = "python", py::arg("step") = 1e-6,
          ("keys: a pose id, or [id] or [id1, id2]. error(x) or error(x1, x2), with " + pose +
           " poses, returns the residual: rows numbers (numpy), rows = information's size "
           "(1.." +
           std::to_string(k) +
           "). information: rows×rows, symmetric positive definite. jacobian(x[, x2]), "
           "optional: a list of one rows×" +
           std::to_string(k) +
           " matrix per pose, d e(x ⊞ τ)/dτ at τ = 0 for x ⊞ τ = x·(Exp(ω), v), τ = "
           "[translation; rotation]; without it, central differences through x ⊞ τ with "
           "`step` (2·poses·" +
           std::to_string(k) + " more calls of error).")
              .c_str())
      .def_property_readonly(
          "keys", [](const Object& o) { return o.keys; }, "the pose ids, one or two")
      .def_property_readonly(
          "rows", [](const Object& o) { return o.model->rows(); }, "the residual's size")
      .def_property_readonly(
          "name", [](const Object& o) { return o.model->name(); }, "the name in messages")
      .def_property_readonly(
          "information", [](const Object& o) { return o.information; }, "Ω, rows×rows")
      .def_property_readonly(
          "has_jacobian", [](const Object& o) { return o.model->hasJacobian(); },
          "True when a jacobian function was given (else central differences)")
      .def(
          "linearize",
          [](const Object& o, const std::vector<G>& poses) {
            if (poses.size() != o.keys.size())
              throw std::invalid_argument("linearize: expected " + std::to_string(o.keys.size()) +
                                          " poses, got " + std::to_string(poses.size()));
            const CustomFactor<G> f = o.make(0, poses.size() == 2 ? 1 : -1);
            typename FactorModel<G>::Jacobians J;
            const auto e = f.error(poses, &J);
            py::list jacobians;
            for (size_t a = 0; a < poses.size(); ++a) jacobians.append(Eigen::MatrixXd(J[a]));
            return py::make_tuple(Eigen::VectorXd(e), jacobians);
          },
          py::arg("poses"),
          "(e, [J per pose]) at the given poses (a list of one or two), as the solvers see them: "
          "J from jacobian() or by central differences.")
      .def("__repr__", [name](const Object& o) {
        std::string keys;
        for (Key id : o.keys) keys += (keys.empty() ? "" : ", ") + std::to_string(id);
        return std::string("<arbor_slam.") + name + " '" + o.model->name() + "' on " + keys + ": " +
               std::to_string(o.model->rows()) + " rows>";
      });
}

}  // namespace

void defineCustomFactors(py::module_& m) {
  defineCustomFactorOf<SE2>(m, "CustomFactor2");
  defineCustomFactorOf<SE3>(m, "CustomFactor3");
}

}  // namespace arbor::python
