# FindArborSuiteSparse: the parts of SuiteSparse Arbor links (CHOLMOD, CCOLAMD and
# SuiteSparse_config), as the imported target ArborSLAM::SuiteSparse. Debian 12's SuiteSparse 5.12
# ships no CMake package, so Arbor brings this module: the build uses it, and the installed
# package (ArborSLAMConfig.cmake) finds it with find_dependency beside itself.
#
# Result: ArborSuiteSparse_FOUND, ArborSuiteSparse_INCLUDE_DIR, ArborSuiteSparse_LIBRARIES and
# the target ArborSLAM::SuiteSparse (include directory and libraries).
include(FindPackageHandleStandardArgs)
find_path(ArborSuiteSparse_INCLUDE_DIR cholmod.h PATH_SUFFIXES suitesparse)
find_library(ArborSuiteSparse_CHOLMOD_LIBRARY cholmod)
find_library(ArborSuiteSparse_CCOLAMD_LIBRARY ccolamd)
find_library(ArborSuiteSparse_CONFIG_LIBRARY suitesparseconfig)
find_package_handle_standard_args(ArborSuiteSparse
  REQUIRED_VARS ArborSuiteSparse_CHOLMOD_LIBRARY ArborSuiteSparse_CCOLAMD_LIBRARY
                ArborSuiteSparse_CONFIG_LIBRARY ArborSuiteSparse_INCLUDE_DIR)
mark_as_advanced(ArborSuiteSparse_INCLUDE_DIR ArborSuiteSparse_CHOLMOD_LIBRARY
                 ArborSuiteSparse_CCOLAMD_LIBRARY ArborSuiteSparse_CONFIG_LIBRARY)
if(ArborSuiteSparse_FOUND)
  set(ArborSuiteSparse_LIBRARIES ${ArborSuiteSparse_CHOLMOD_LIBRARY}
      ${ArborSuiteSparse_CCOLAMD_LIBRARY} ${ArborSuiteSparse_CONFIG_LIBRARY})
  if(NOT TARGET ArborSLAM::SuiteSparse)
    add_library(ArborSLAM::SuiteSparse INTERFACE IMPORTED)
    set_target_properties(ArborSLAM::SuiteSparse PROPERTIES
      INTERFACE_INCLUDE_DIRECTORIES "${ArborSuiteSparse_INCLUDE_DIR}"
      INTERFACE_LINK_LIBRARIES "${ArborSuiteSparse_LIBRARIES}")
  endif()
endif()
