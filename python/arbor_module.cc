// The Python module `arbor_slam` (docs/python.md): pose-graph files, batch solvers and the online
// smoother with its covariances. C++ exceptions become Python exceptions with the same message:
// std::invalid_argument and std::out_of_range (an unknown id) ValueError, arbor::FileError
// arbor_slam.FileError (a RuntimeError), arbor::FactorError the exception a factor's own function
// raised (with a note naming the factor) or arbor_slam.FactorError (a ValueError), anything else
// RuntimeError.
#include <stdexcept>

#include <pybind11/pybind11.h>

#include "arbor_slam/core/factor_error.h"
#include "arbor_slam/io/pose_graph_file.h"
#include "bindings.h"
#include "custom_factor_object.h"

#ifndef ARBOR_VERSION
#define ARBOR_VERSION "unknown"
#endif

PYBIND11_MODULE(arbor_slam, m) {
  namespace py = pybind11;
  m.doc() = "Arbor: an incremental pose-graph smoother (iSAM2 style) and batch solvers";
  m.attr("__version__") = ARBOR_VERSION;
  py::register_exception<arbor::FileError>(m, "FileError", PyExc_RuntimeError).attr("__doc__") =
      "A malformed or unreadable file: the message is `path:line: what was wrong`.";
  // A factor of your own that failed in an update (arbor::FactorError): the exception its own
  // function raised, with a note naming the factor, its poses and their values; a failure
  // found by the library (a non-finite or misshapen result) arbor_slam.FactorError.
  static py::exception<arbor::FactorError> factor_error(m, "FactorError", PyExc_ValueError);
  factor_error.attr("__doc__") =
      "A factor of your own failed in an update (a non-finite or misshapen result): the message "
      "names the factor, its poses and their values. The update applied nothing.";
  py::register_exception_translator([](std::exception_ptr p) {
    try {
      if (p) std::rethrow_exception(p);
    } catch (const std::out_of_range& e) {
      PyErr_SetString(PyExc_ValueError, e.what());
    } catch (const arbor::FactorError& e) {
      if (!arbor::python::raiseCause(e)) PyErr_SetString(factor_error.ptr(), e.what());
    }
  });
  arbor::python::definePoses(m);
  arbor::python::defineCustomFactors(m);
  arbor::python::defineGraphs(m);
  arbor::python::defineSolve(m);
  arbor::python::defineSmootherResults(m);
  arbor::python::defineSmoother(m);
}
