// The Python module `arbor_slam` (docs/python.md): pose-graph files, batch solvers and the online
// smoother with its covariances. C++ exceptions become Python exceptions with the same message:
// std::invalid_argument and std::out_of_range (an unknown id) ValueError, arbor::FileError
// arbor_slam.FileError (a RuntimeError), anything else RuntimeError.
#include <stdexcept>

#include <pybind11/pybind11.h>

#include "arbor_slam/io/pose_graph_file.h"
#include "bindings.h"

#ifndef ARBOR_VERSION
#define ARBOR_VERSION "unknown"
#endif

PYBIND11_MODULE(arbor_slam, m) {
  namespace py = pybind11;
  m.doc() = "Arbor: an incremental pose-graph smoother (iSAM2 style) and batch solvers";
  m.attr("__version__") = ARBOR_VERSION;
  py::register_exception<arbor::FileError>(m, "FileError", PyExc_RuntimeError).attr("__doc__") =
      "A malformed or unreadable file: the message is `path:line: what was wrong`.";
  py::register_exception_translator([](std::exception_ptr p) {
    try {
      if (p) std::rethrow_exception(p);
    } catch (const std::out_of_range& e) {
      PyErr_SetString(PyExc_ValueError, e.what());
    }
  });
  arbor::python::definePoses(m);
  arbor::python::defineCustomFactors(m);
  arbor::python::defineGraphs(m);
  arbor::python::defineSolve(m);
  arbor::python::defineSmootherResults(m);
  arbor::python::defineSmoother(m);
}
