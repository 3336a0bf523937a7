# What `cmake --install` puts under the prefix (docs/library.md): the public libraries and their
# headers (PREFIX/include/arbor_slam/), the `arbor` tool (and arbor-bench when built), the jar of
# the Java LCM types, the CMake package ArborSLAM (ArborSLAM::core, ArborSLAM::bayestree,
# ArborSLAM::io, ArborSLAM::lcm, ArborSLAM::arbor) and arbor-slam.pc. The names avoid arbor-sim's
# (docs/library.md, "Names").
include(CMakePackageConfigHelpers)

set(arbor_public_targets arbor_core arbor_bayestree arbor_io arbor_lcm arbor_all)
install(TARGETS ${arbor_public_targets} EXPORT ArborSLAMTargets
  LIBRARY DESTINATION ${CMAKE_INSTALL_LIBDIR}
  ARCHIVE DESTINATION ${CMAKE_INSTALL_LIBDIR}
  RUNTIME DESTINATION ${CMAKE_INSTALL_BINDIR})

# Headers: every header of core/, bayestree/ and io/ but the internal ones no public header
# includes (they need a dependency's headers: omp.h, or are the initialisers' shared helpers).
foreach(dir core bayestree io)
  install(DIRECTORY ${PROJECT_SOURCE_DIR}/${dir}/
    DESTINATION ${CMAKE_INSTALL_INCLUDEDIR}/arbor_slam/${dir}
    FILES_MATCHING PATTERN "*.h"
    PATTERN "*_internal.h" EXCLUDE
    PATTERN "serial_openmp.h" EXCLUDE
    PATTERN "lcm" EXCLUDE)
endforeach()
# (lcm-gen's message types, included by arbor_slam/io/lcm_messages.h as "arbor/<type>.hpp", are
# installed to PREFIX/include/arbor_slam/lcm/arbor/ by io/CMakeLists.txt.)

install(TARGETS arbor RUNTIME DESTINATION ${CMAKE_INSTALL_BINDIR})
if(TARGET arbor-bench)
  # OPTIONAL: an install after building only some targets still works.
  install(TARGETS arbor-bench RUNTIME DESTINATION ${CMAKE_INSTALL_BINDIR} OPTIONAL)
endif()

# `arbor plot` looks for its drawing script in PREFIX/share/arbor/ (tools/cli/plot_command.cc).
install(PROGRAMS ${PROJECT_SOURCE_DIR}/tools/plots/plot_trajectory.py
  DESTINATION ${CMAKE_INSTALL_DATADIR}/arbor)

# `arbor spy` looks for the jar in PREFIX/share/arbor/ (tools/cli/spy_command.cc).
set(ARBOR_INSTALL_JAR ${CMAKE_INSTALL_DATADIR}/arbor/arbor_lcm_types.jar)
if(TARGET arbor_lcm_java)
  install(FILES ${PROJECT_BINARY_DIR}/io/arbor_lcm_types.jar
    DESTINATION ${CMAKE_INSTALL_DATADIR}/arbor)
endif()

# The CMake package.
install(EXPORT ArborSLAMTargets NAMESPACE ArborSLAM:: DESTINATION ${ARBOR_INSTALL_CMAKEDIR})
configure_package_config_file(${PROJECT_SOURCE_DIR}/cmake/ArborSLAMConfig.cmake.in
  ${PROJECT_BINARY_DIR}/ArborSLAMConfig.cmake
  INSTALL_DESTINATION ${ARBOR_INSTALL_CMAKEDIR}
  PATH_VARS CMAKE_INSTALL_INCLUDEDIR ARBOR_INSTALL_JAR)
# 0.x: only the same minor version is compatible (its ABI may change), as the SONAME says.
if(PROJECT_VERSION_MAJOR EQUAL 0)
  set(arbor_compatibility SameMinorVersion)
else()
  set(arbor_compatibility SameMajorVersion)
endif()
write_basic_package_version_file(${PROJECT_BINARY_DIR}/ArborSLAMConfigVersion.cmake
  VERSION ${PROJECT_VERSION} COMPATIBILITY ${arbor_compatibility})
install(FILES ${PROJECT_BINARY_DIR}/ArborSLAMConfig.cmake
  ${PROJECT_BINARY_DIR}/ArborSLAMConfigVersion.cmake
  ${PROJECT_SOURCE_DIR}/cmake/FindArborSuiteSparse.cmake
  DESTINATION ${ARBOR_INSTALL_CMAKEDIR})

# arbor-slam.pc: Libs.private lists the link-only dependencies (for -DBUILD_SHARED_LIBS=OFF).
set(arbor_pc_private "")
foreach(lib ${ArborSuiteSparse_LIBRARIES} ${LAPACK_LIBRARIES} ${ZLIB_LIBRARIES} ${CMAKE_DL_LIBS}
            gomp)
  if(IS_ABSOLUTE "${lib}")
    get_filename_component(name "${lib}" NAME_WE)
    string(REGEX REPLACE "^lib" "" name "${name}")
    list(APPEND arbor_pc_private "-l${name}")
  elseif(NOT lib MATCHES "^-")
    list(APPEND arbor_pc_private "-l${lib}")
  else()
    list(APPEND arbor_pc_private "${lib}")
  endif()
endforeach()
list(REMOVE_DUPLICATES arbor_pc_private)
list(JOIN arbor_pc_private " " ARBOR_PC_LIBS_PRIVATE)
if(IS_ABSOLUTE "${CMAKE_INSTALL_LIBDIR}")
  set(ARBOR_PC_TO_PREFIX "${CMAKE_INSTALL_PREFIX}")
  message(WARNING
    "CMAKE_INSTALL_LIBDIR is absolute: arbor-slam.pc names the prefix ${CMAKE_INSTALL_PREFIX}")
else()
  file(RELATIVE_PATH ARBOR_PC_TO_PREFIX ${CMAKE_INSTALL_FULL_LIBDIR}/pkgconfig
    ${CMAKE_INSTALL_PREFIX})
endif()
configure_file(${PROJECT_SOURCE_DIR}/cmake/arbor-slam.pc.in ${PROJECT_BINARY_DIR}/arbor-slam.pc @ONLY)
install(FILES ${PROJECT_BINARY_DIR}/arbor-slam.pc DESTINATION ${CMAKE_INSTALL_LIBDIR}/pkgconfig)
