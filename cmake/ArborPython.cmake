# The Python module `arbor_slam` (python/, pybind11): ARBOR_PYTHON, ON when pybind11 and a Python 3
# interpreter with numpy are found. The interpreter: Python3_EXECUTABLE when given, else the
# first of /usr/bin/python3 and the python3 on PATH that imports numpy (a pyenv python3 on PATH
# often lacks Debian's numpy). Installed into ARBOR_PYTHON_INSTALL_DIR (relative to the prefix:
# lib/python3/dist-packages, Debian's directory for modules of every Python 3). docs/python.md.

if(NOT Python3_EXECUTABLE)
  find_program(arbor_path_python3 python3)
  foreach(candidate /usr/bin/python3 ${arbor_path_python3})
    if(EXISTS "${candidate}")
      execute_process(COMMAND "${candidate}" -c "import numpy"
                      RESULT_VARIABLE arbor_numpy_missing OUTPUT_QUIET ERROR_QUIET)
      if(arbor_numpy_missing EQUAL 0)
        set(Python3_EXECUTABLE "${candidate}" CACHE FILEPATH "Python 3 for the arbor_slam module")
        break()
      endif()
    endif()
  endforeach()
endif()

set(arbor_python_found OFF)
if(Python3_EXECUTABLE)
  find_package(Python3 COMPONENTS Interpreter Development.Module QUIET)
  if(Python3_FOUND)
    find_package(pybind11 2.6 CONFIG QUIET)
    if(pybind11_FOUND)
      set(arbor_python_found ON)
    endif()
  endif()
endif()

option(ARBOR_PYTHON "Build the Python module arbor_slam (pybind11)" ${arbor_python_found})
set(ARBOR_PYTHON_INSTALL_DIR "lib/python3/dist-packages" CACHE STRING
    "Where cmake --install puts the Python module (relative to the prefix, or absolute)")

if(ARBOR_PYTHON)
  if(NOT arbor_python_found)
    message(FATAL_ERROR "ARBOR_PYTHON needs pybind11 (python3-pybind11 or pybind11-dev), the "
                        "Python 3 headers (python3-dev) and a python3 with numpy "
                        "(python3-numpy); or configure with -DARBOR_PYTHON=OFF")
  endif()
  execute_process(COMMAND "${Python3_EXECUTABLE}" -c "import pytest"
                  RESULT_VARIABLE arbor_pytest_missing OUTPUT_QUIET ERROR_QUIET)
  if(arbor_pytest_missing EQUAL 0)
    set(ARBOR_PYTEST_FOUND ON)
  endif()
  message(STATUS "Python module arbor_slam: ${Python3_EXECUTABLE} (pybind11 ${pybind11_VERSION})")
  add_subdirectory(python)
endif()
