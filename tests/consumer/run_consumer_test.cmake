# ctest install_consumer (tests/CMakeLists.txt), run with cmake -P: installs the build tree into
# a fresh prefix, then, as a user would,
#   1. configures and builds tests/consumer (find_package(ArborSLAM), ArborSLAM::arbor) against it
#      (its CMakeLists checks ARBOR_INCLUDE_DIR and ARBOR_LCM_TYPES_JAR point into the prefix) and
#      replays each DATA file with it; its F must equal the installed `arbor replay`'s F_final
#      (within 1e-9 relative), and OpenBLAS must run one thread per call without the program
#      asking (unless the BLAS is not OpenBLAS); it also solves a graph with a factor of its own
#      (an autodiff functor in main.cc, through the installed arbor_slam/core/autodiff_factor.h);
#   2. compiles pkg_config_check.cc with `pkg-config --cflags --libs arbor-slam` alone
#      (PKG_CONFIG_PATH into the prefix) and runs it.
#   3. with PYTHON (ARBOR_PYTHON on): imports the installed module `arbor_slam` (PYTHONPATH into
#      the prefix's PYTHON_DIR) and replays each DATA file with it to the same F
#      (python_consumer.py).
# Variables: BUILD_DIR, SOURCE_DIR, WORK_DIR, LIBDIR (CMAKE_INSTALL_LIBDIR), DATA (files
# separated by |), CXX, LAUNCHER (may be empty), PKG_CONFIG; PYTHON and PYTHON_DIR (relative
# to the prefix) when the module is built.
cmake_minimum_required(VERSION 3.19)  # string(JSON)
string(REPLACE "|" ";" DATA "${DATA}")

function(run)
  execute_process(COMMAND ${ARGN} RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
  if(NOT rc EQUAL 0)
    list(JOIN ARGN " " command)
    message(FATAL_ERROR "failed (${rc}): ${command}\n${out}\n${err}")
  endif()
  set(out "${out}" PARENT_SCOPE)
endfunction()

set(prefix ${WORK_DIR}/prefix)
file(REMOVE_RECURSE ${WORK_DIR})
run(${CMAKE_COMMAND} --install ${BUILD_DIR} --prefix ${prefix})
foreach(installed bin/arbor include/arbor_slam/core/se2.h
        include/arbor_slam/bayestree/online_smoother.h include/arbor_slam/io/pose_graph_file.h
        include/arbor_slam/io/lcm_messages.h include/arbor_slam/lcm/arbor/edge_t.hpp
        ${LIBDIR}/cmake/ArborSLAM/ArborSLAMConfig.cmake
        ${LIBDIR}/cmake/ArborSLAM/ArborSLAMConfigVersion.cmake
        ${LIBDIR}/cmake/ArborSLAM/FindArborSuiteSparse.cmake ${LIBDIR}/pkgconfig/arbor-slam.pc)
  if(NOT EXISTS ${prefix}/${installed})
    message(FATAL_ERROR "not installed: ${prefix}/${installed}")
  endif()
endforeach()
# Nothing under arbor-sim's include/arbor/ or lib/cmake/Arbor/ (docs/library.md, "Names").
foreach(internal include/arbor_slam/tools include/arbor_slam/core/serial_openmp.h
        include/arbor_slam/core/initialization_internal.h include/arbor ${LIBDIR}/cmake/Arbor)
  if(EXISTS ${prefix}/${internal})
    message(FATAL_ERROR "installed but internal: ${prefix}/${internal}")
  endif()
endforeach()

# 1. The CMake package.
set(configure ${CMAKE_COMMAND} -S ${SOURCE_DIR}/tests/consumer -B ${WORK_DIR}/consumer
    -DCMAKE_BUILD_TYPE=Release -DCMAKE_PREFIX_PATH=${prefix} -DCMAKE_CXX_COMPILER=${CXX}
    -DARBOR_EXPECTED_PREFIX=${prefix})
if(LAUNCHER)
  list(APPEND configure -DCMAKE_CXX_COMPILER_LAUNCHER=${LAUNCHER})
endif()
run(${configure})
run(${CMAKE_COMMAND} --build ${WORK_DIR}/consumer)
foreach(file ${DATA})
  run(${CMAKE_COMMAND} -E env --unset=OPENBLAS_NUM_THREADS ${prefix}/bin/arbor replay ${file}
      --json)
  string(JSON expected GET "${out}" F_final)
  run(${CMAKE_COMMAND} -E env --unset=OPENBLAS_NUM_THREADS ${WORK_DIR}/consumer/arbor_consumer
      ${file} ${expected})
  message(STATUS "${file}: arbor replay F_final ${expected}; consumer ${out}")
  if(NOT out MATCHES "blas_threads (1|none)\n")
    message(FATAL_ERROR "the consumer's OpenBLAS does not run one thread per call:\n${out}")
  endif()
  if(NOT out MATCHES "custom_factor ok\n")  # its own autodiff factor, solved twice
    message(FATAL_ERROR "the consumer's own factor did not reach the truth:\n${out}")
  endif()
  if(PYTHON)
    run(${CMAKE_COMMAND} -E env PYTHONPATH=${prefix}/${PYTHON_DIR} --unset=OPENBLAS_NUM_THREADS
        ${PYTHON} ${SOURCE_DIR}/tests/consumer/python_consumer.py ${prefix} ${file} ${expected})
    message(STATUS "${out}")
  endif()
endforeach()

# 2. pkg-config.
execute_process(COMMAND ${CMAKE_COMMAND} -E env PKG_CONFIG_PATH=${prefix}/${LIBDIR}/pkgconfig
                ${PKG_CONFIG} --cflags --libs arbor-slam
                RESULT_VARIABLE rc OUTPUT_VARIABLE flags ERROR_VARIABLE err
                OUTPUT_STRIP_TRAILING_WHITESPACE)
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "pkg-config --cflags --libs arbor-slam failed:\n${err}")
endif()
message(STATUS "pkg-config --cflags --libs arbor-slam: ${flags}")
separate_arguments(flags UNIX_COMMAND "${flags}")
run(${CXX} -std=c++17 ${SOURCE_DIR}/tests/consumer/pkg_config_check.cc ${flags}
    -o ${WORK_DIR}/pkg_config_check)
list(GET DATA 0 file)
run(${CMAKE_COMMAND} -E env LD_LIBRARY_PATH=${prefix}/${LIBDIR} ${WORK_DIR}/pkg_config_check ${file})
if(NOT out MATCHES "^poses [1-9][0-9]* edges [1-9]")
  message(FATAL_ERROR "pkg_config_check printed: ${out}")
endif()
message(STATUS "pkg_config_check: ${out}")
